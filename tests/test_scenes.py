"""Built-in scenes and XML loading (foveated_mi.scenes).

References are independent NumPy computations: a voxel-by-voxel face count, the look-at
matrix built from its definition, and a Snellen "E" drawn by hand.
"""
import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

import tolerances
from foveated_mi import scenes
from foveated_mi.validate import ParameterError

SMALL = {"cornell-box": {}, "voxel-city": {"size": 24}, "eye-exam": {}}
PATH3 = {"type": "path", "max_depth": 3}


def _triangles(scene) -> int:
    """Triangles of a scene: meshes count their faces, a rectangle counts 2."""
    total = 0
    for s in scene.shapes():
        params = mi.traverse(s)
        if "faces" in params:
            total += int(dr.width(params["faces"]) // 3)
        else:
            assert str(s).startswith("Rectangle"), str(s)[:40]
            total += 2
    return total


@pytest.mark.parametrize("name", list(scenes.SCENES))
def test_builtin_loads_and_renders(name):
    scene = scenes.load_scene(name, width=32, height=32, spp=1, integrator=PATH3,
                              **SMALL[name])
    sensor = scene.sensors()[0]
    film = sensor.film()
    assert tuple(film.size()) == (32, 32)
    assert "BoxFilter" in str(film.rfilter())
    assert "IndependentSampler" in str(sensor.sampler())
    assert "PerspectiveCamera" in str(sensor)
    img = np.array(mi.render(scene, spp=1))
    assert img.shape == (32, 32, 3)
    assert np.isfinite(img).all()
    assert img.mean() > 0.02, f"{name} renders black"
    assert (img.reshape(-1, 3).max(axis=1) > 0).mean() > 0.5


def test_scene_dict_defaults_and_overrides():
    d = scenes.scene_dict("cornell-box", width=40, height=20, spp=3)
    assert d["integrator"] == {"type": "path", "max_depth": 6}
    assert d["sensor"]["film"] == {"type": "hdrfilm", "width": 40, "height": 20,
                                   "rfilter": {"type": "box"}, "pixel_format": "rgb"}
    assert d["sensor"]["sampler"] == {"type": "independent", "sample_count": 3}
    d = scenes.scene_dict("cornell-box", integrator={"type": "direct"})
    assert d["integrator"] == {"type": "direct"}


@pytest.mark.parametrize("bad", ["nope", "/no/such/scene.xml", 3])
def test_unknown_scene_is_one_line_error(bad):
    with pytest.raises(ParameterError) as e:
        scenes.load_scene(bad)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("scene = ")
    assert repr(bad) in msg and "'voxel-city'" in msg and "'eye-exam'" in msg


def test_unknown_builtin_parameter():
    with pytest.raises(ParameterError, match=r"voxel-city\.sise = 3 .*size"):
        scenes.scene_dict("voxel-city", sise=3)
    with pytest.raises(ParameterError, match="size = 2"):
        scenes.scene_dict("voxel-city", size=2)
    with pytest.raises(ParameterError, match="width = 0"):
        scenes.load_scene("cornell-box", width=0)


def _brute_force_voxel_triangles(h: np.ndarray) -> dict:
    """Exposed faces counted voxel by voxel on a 3-D occupancy grid."""
    n = h.shape[0]
    top = int(h.max()) + 1
    occ = np.zeros((n + 2, n + 2, top), dtype=bool)          # one empty cell of margin
    for i in range(n):
        for j in range(n):
            occ[i + 1, j + 1, :h[i, j]] = True
    inner = occ[1:-1, 1:-1]
    faces = {
        "+x": int((inner & ~occ[2:, 1:-1]).sum()), "-x": int((inner & ~occ[:-2, 1:-1]).sum()),
        "+z": int((inner & ~occ[1:-1, 2:]).sum()), "-z": int((inner & ~occ[1:-1, :-2]).sum()),
        "+y": n * n,                                          # one top per column (streets too)
    }
    return faces


def test_voxel_city_triangles_match_brute_force_and_normals_point_out():
    size = 24
    h, kind = scenes.voxel_city_heights(size, seed=3)
    assert h.shape == kind.shape == (size, size) and h.min() >= 0 and h.max() > 0
    ref = _brute_force_voxel_triangles(h)
    expected = 2 * sum(ref.values()) + 2                      # + the ground rectangle
    assert scenes.voxel_city_triangle_count(size, seed=3) == expected
    scene = scenes.load_scene("voxel-city", size=size, seed=3, width=8, height=8)
    assert _triangles(scene) == expected
    # Face normals of the city mesh, by direction: outward and as many as exposed faces.
    mesh = [s for s in scene.shapes() if "faces" in mi.traverse(s)][0]
    p = mi.traverse(mesh)
    v = np.array(p["vertex_positions"]).reshape(-1, 3)
    f = np.array(p["faces"]).reshape(-1, 3)
    nrm = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    axes = {"+x": [1, 0, 0], "-x": [-1, 0, 0], "+y": [0, 1, 0], "+z": [0, 0, 1],
            "-z": [0, 0, -1]}
    for key, axis in axes.items():
        assert int((nrm @ np.array(axis) > 0.999).sum()) == 2 * ref[key], key
    assert int((nrm[:, 1] < -0.5).sum()) == 0                 # no bottoms
    # Every face separates a filled voxel (behind it) from an empty one (in front of it).
    scale = scenes.CITY_EXTENT / size
    vox = v / scale + [size / 2, 0.0, size / 2]               # world -> voxel units
    centre = (vox[f[:, 0]] + vox[f[:, 1]] + vox[f[:, 2]]) / 3

    def filled(p):
        i, y, j = (np.floor(p[:, k]).astype(int) for k in range(3))
        inside = (i >= 0) & (i < size) & (j >= 0) & (j < size)
        out = y < 0                                           # below the street: ground
        hi = h[np.clip(i, 0, size - 1), np.clip(j, 0, size - 1)]
        return out | (inside & (y >= 0) & (y < hi))

    assert filled(centre - 0.5 * nrm).all()
    assert not filled(centre + 0.5 * nrm).any()
    assert np.allclose(v[:, [0, 2]].min(axis=0), -scenes.CITY_EXTENT / 2)


def test_voxel_city_triangle_count_grows_past_a_million():
    counts = {}
    for size in (32, 64, 128, 200):
        h, _ = scenes.voxel_city_heights(size)
        counts[size] = 2 * sum(_brute_force_voxel_triangles(h).values()) + 2
        assert scenes.voxel_city_triangle_count(size) == counts[size]
    assert counts[32] < counts[64] < counts[128] < counts[200]
    assert 1e5 < counts[128] < 1e6            # the default: a few hundred thousand
    assert counts[200] > 1_000_000


def test_envmap_switch():
    with_sky = scenes.load_scene("voxel-city", size=12, width=8, height=8)
    no_sky = scenes.load_scene("voxel-city", size=12, width=8, height=8, envmap=False)
    assert with_sky.environment() is not None
    assert no_sky.environment() is None
    assert len(no_sky.emitters()) == 1        # the sun only
    with pytest.raises(ParameterError, match="envmap = 'no'"):
        scenes.scene_dict("voxel-city", envmap="no")


def _snellen_e(quarter_turns: int) -> np.ndarray:
    e = np.ones((5, 5), dtype=bool)
    e[1, 1:] = False
    e[3, 1:] = False
    return np.rot90(e, quarter_turns)


def test_eye_exam_is_small_and_its_chart_is_detailed():
    scene = scenes.load_scene("eye-exam", width=16, height=16)
    assert _triangles(scene) <= 40
    img, letters = scenes.eye_chart()
    lo, hi = float(img.min()), float(img.max())
    assert (hi - lo) / (hi + lo) > 0.9                        # Michelson contrast
    assert min(L["size"] for L in letters) == 5               # one-texel strokes
    assert len({L["quarter_turns"] for L in letters}) == 4
    for L in letters:                                         # every glyph is a Snellen E
        s, x, y = L["size"], L["x"], L["y"]
        patch = img[y:y + s, x:x + s][s // 10::s // 5, s // 10::s // 5] < 0.5
        assert np.array_equal(patch, _snellen_e(L["quarter_turns"])), L
    ink = img < 0.5                                           # letters do not overlap
    assert ink.sum() == sum(_snellen_e(0).sum() * (L["size"] // 5) ** 2 for L in letters)


def test_eye_exam_camera_centre_sees_fine_letters():
    scene = scenes.load_scene("eye-exam", width=16, height=16)
    img, letters = scenes.eye_chart()
    H, W = img.shape
    # Rays through the central 8 % x 8 % of the film.
    n = 64
    a = (np.arange(n) + 0.5) / n * 0.08 + 0.46
    xs, ys = np.meshgrid(a, a)
    ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, mi.Point2f(xs.ravel(), ys.ravel()),
                                           mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    assert bool(dr.all(si.is_valid()))
    # All on the chart's plane: a float32 intersection, o + t d or the vertices' (rounded)
    # interpolation, 8 roundings on terms of size |o| + t + |z|.
    scale = np.abs(np.array(ray.o.z)) + np.array(si.t) + 3.97
    tolerances.assert_within(np.array(si.p.z), -3.97, tolerances.chain_bound(scale, 8), "plane")
    # Reflectance as rendered, against the NumPy chart at the same texture coordinates
    # (image row 0 is the chart's top: texture v grows upwards).
    rendered = np.array(si.bsdf().eval_diffuse_reflectance(si))[0]
    u, v = np.array(si.uv.x), np.array(si.uv.y)
    expected = img[np.clip(((1 - v) * H).astype(int), 0, H - 1),
                   np.clip((u * W).astype(int), 0, W - 1)]
    assert np.mean(np.abs(rendered - expected) < 0.2) > 0.8
    # High-frequency detail: many ink/paper transitions along each row of rays, and the
    # letters there are the chart's finest (strokes of 1 or 2 texels).
    ink = (rendered < 0.5).reshape(n, n)
    assert 0.1 < ink.mean() < 0.6
    assert np.mean(np.abs(np.diff(ink.astype(int), axis=1)).sum(axis=1)) > 8
    cx, cy = u.mean() * W, (1 - v.mean()) * H
    near = [L for L in letters if abs(L["x"] + L["size"] / 2 - cx) < 40
            and abs(L["y"] + L["size"] / 2 - cy) < 40]
    assert len(near) >= 5 and max(L["size"] for L in near) <= 10


def _look_at_bound(ref, origin=None):
    """Float32 look-at (Mitsuba) against float64: the inputs' roundings, the direction's
    subtraction and normalisation, two cross products and normalisations, ~24 roundings on
    unit vectors (terms of size <= 1 each): 24 on |ref| + 1; the origin (a 4x4 matrix's
    translation, or ``origin`` added to a unit vector) is rounded once."""
    ref = np.asarray(ref, np.float64)
    bound = tolerances.chain_bound(np.abs(ref) + 1.0, 24)
    if ref.shape == (4, 4):
        bound[:3, 3] = tolerances.chain_bound(ref[:3, 3], 1)
    if origin is not None:
        bound = tolerances.chain_bound(origin, 1) + tolerances.chain_bound(2.0, 24)
    return bound


def _look_at_ref(origin, target, up):
    d = np.subtract(target, origin, dtype=float)
    d /= np.linalg.norm(d)
    left = np.cross(up, d)
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, origin
    return m


def test_apply_camera_and_camera_of():
    scene = scenes.load_scene("cornell-box", width=16, height=16)
    cam = dict(origin=[0.3, 0.2, 3.0], target=[0.0, -0.1, 0.0], up=[0.1, 1.0, 0.0], fov=50.0)
    scenes.apply_camera(scene, cam)
    m = np.array(scene.sensors()[0].world_transform().matrix).reshape(4, 4)
    ref = _look_at_ref(cam["origin"], cam["target"], cam["up"])
    tolerances.assert_within(m, ref, _look_at_bound(ref), "look_at")
    got = scenes.camera_of(scene)
    tolerances.assert_within(got["origin"], cam["origin"], tolerances.chain_bound(cam["origin"], 1),
                             "origin")
    d = np.subtract(cam["target"], cam["origin"])
    tolerances.assert_within(np.subtract(got["target"], got["origin"]), d / np.linalg.norm(d),
                             _look_at_bound(d / np.linalg.norm(d)), "direction")
    assert got["fov"] == pytest.approx(50.0)
    with pytest.raises(ParameterError, match="camera.fov"):
        scenes.apply_camera(scene, {**cam, "fov": 0})


def test_apply_camera_moves_the_principal_point_as_loading_with_it_does():
    """An off-axis eye moved in place sees what one loaded at that pose sees: the same ray
    through every film point (the principal point is applied, not dropped)."""
    cam = dict(origin=[0.3, 0.2, 3.0], target=[0.0, -0.1, 0.0], up=[0.0, 1.0, 0.0], fov=60.0,
               principal_point=[0.12, -0.08])
    loaded = scenes.load_scene("cornell-box", width=16, height=16, camera=cam).sensors()[0]
    moved_scene = scenes.load_scene("cornell-box", width=16, height=16)
    scenes.apply_camera(moved_scene, cam)
    moved = moved_scene.sensors()[0]
    uv = mi.Point2f(mi.Float([0.0, 0.5, 1.0, 0.2]), mi.Float([0.0, 0.5, 1.0, 0.9]))
    a, _ = loaded.sample_ray(0.0, 0.5, uv, mi.Point2f(0.5, 0.5))
    b, _ = moved.sample_ray(0.0, 0.5, uv, mi.Point2f(0.5, 0.5))
    # The same sensor parameters through the same arithmetic.
    np.testing.assert_array_equal(np.array(a.d), np.array(b.d))
    # ... and not the centred frustum's.
    centred, _ = scenes.load_scene("cornell-box", width=16, height=16, camera={
        k: v for k, v in cam.items() if k != "principal_point"}).sensors()[0].sample_ray(
        0.0, 0.5, uv, mi.Point2f(0.5, 0.5))
    assert np.abs(np.array(centred.d) - np.array(b.d)).max() > 0.05


def test_xml_scene_size_spp_and_integrator_override(shared_scene):
    path = shared_scene("voxel-monument")
    scene = scenes.load_scene(path, width=24, height=16, spp=2,
                              integrator={"type": "aov", "aovs": "dd:depth",
                                          "img": {"type": "path", "max_depth": 2}})
    sensor = scene.sensors()[0]
    assert tuple(sensor.film().size()) == (24, 16)
    assert sensor.sampler().sample_count() == 2
    assert "AOVIntegrator" in str(scene.integrator()) and "max_depth = 2" in str(
        scene.integrator())
    img = np.array(mi.render(scene))
    assert img.shape == (16, 24, 4) and np.isfinite(img).all() and img[..., :3].mean() > 0
    # The camera read from the file without loading it equals the loaded sensor's.
    a, b = scenes.scene_camera(path), scenes.camera_of(scene)
    tolerances.assert_within(b["origin"], a["origin"], tolerances.chain_bound(a["origin"], 1),
                             "origin")
    tolerances.assert_within(b["target"], a["target"], _look_at_bound(a["target"], a["origin"]),
                             "target")
    tolerances.assert_within(b["up"], a["up"], _look_at_bound(a["up"]), "up")
    assert a["fov"] == pytest.approx(b["fov"])
    # A camera override on an XML sensor (fov along x whatever the file said).
    cam = dict(origin=[200.0, -100.0, 150.0], target=[50.0, 50.0, 40.0], up=[0, 0, 1], fov=30.0)
    moved = scenes.load_scene(path, width=24, height=16, camera=cam)
    m = np.array(moved.sensors()[0].world_transform().matrix).reshape(4, 4)
    ref = _look_at_ref(cam["origin"], cam["target"], cam["up"])
    tolerances.assert_within(m, ref, _look_at_bound(ref), "look_at")
    assert scenes.camera_of(moved)["fov"] == pytest.approx(30.0)
    # Nothing overridden: the file's own film, and the search path is left as it was.
    resolver_before = list(mi.file_resolver())
    plain = scenes.load_scene(path, width=8)
    assert tuple(plain.sensors()[0].film().size()) == (8, 1024)
    assert list(mi.file_resolver()) == resolver_before


def test_xml_scene_bad_parameter_is_one_line(shared_scene):
    path = shared_scene("voxel-monument")
    with pytest.raises(ParameterError) as e:
        scenes.load_scene(path, resx=40)
    assert "\n" not in str(e.value) and "resx" in str(e.value) and path in str(e.value)
