"""Reuse between the eyes: the second eye's samples that the first eye's stand for are exact
where the nested integrator is deterministic, never disoccluded (a thin card in front of one
eye), never glossy, and the second eye traces only the rest."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.stereo import EYES, Frustum, Stereo, StereoRig, crescent
from foveated_mi.validate import ParameterError

FRUSTUM = Frustum(45.0, 35.0, 40.0, 40.0)
WIDTH = 64


class Albedo(mi.SamplingIntegrator):
    """The diffuse albedo at the primary hit (0 on a miss): a deterministic radiance, the same
    from every eye, for every sample that lands on one face."""

    def sample(self, scene, sampler, ray, medium=None, active=True):
        si = scene.ray_intersect(mi.Ray3f(ray), active)
        ok = si.is_valid() & active
        value = si.bsdf().eval_diffuse_reflectance(si, ok)
        return dr.select(ok, mi.Spectrum(value), self.missed(scene, si, active & ~ok)), \
            mi.Bool(True), []

    def missed(self, scene, si, active):
        """The radiance of a ray that hit nothing."""
        return mi.Spectrum(0.0)

    def to_string(self):
        return "Albedo"


mi.register_integrator("test_albedo", lambda props: Albedo(props))


def _diffuse(rgb):
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": rgb}}


def _head(integrator: str) -> dict:
    """A scene's integrator and its sensor: a head at the origin looking down +z, 80° wide,
    WIDTH pixels square, a box filter, one sample a pixel."""
    return {"type": "scene", "integrator": {"type": integrator},
            "sensor": {"type": "perspective", "fov": 80,
                       "to_world": mi.ScalarTransform4f().look_at(
                           origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": WIDTH, "height": WIDTH,
                                "rfilter": {"type": "box"}},
                       "sampler": {"type": "independent", "sample_count": 1}}}


def _scene(glossy: bool = False):
    """A wall of flat-coloured tiles and a floor, seen by a head at the origin looking down
    +z, a thin card 0.25 in front of the left eye (0.0315 to its side), which hides from
    the left eye part of the wall the right eye sees, and another 0.4 in front of the right
    eye, lower, which does the converse. Every face looks at the eyes: only the plane test
    tells a card from the wall behind it. The tiles stand at depths 0.12 or more
    apart, more than the plane test's tolerance there (0.02 of the distance): no two
    neighbours share a plane."""
    d = {**_head("test_albedo"),
         "card": {"type": "rectangle", "bsdf": _diffuse([0.9, 0.1, 0.1]),
                  "to_world": mi.ScalarTransform4f().translate([0.0315, 0.0, 0.25])
                  .scale([0.012, 0.2, 1.0]).rotate([0, 1, 0], 180)},
         "low_card": {"type": "rectangle", "bsdf": _diffuse([0.1, 0.8, 0.8]),
                      "to_world": mi.ScalarTransform4f().translate([-0.0315, -0.12, 0.4])
                      .scale([0.015, 0.1, 1.0]).rotate([0, 1, 0], 180)}}
    colours = [[0.2, 0.5, 0.3], [0.6, 0.6, 0.2], [0.3, 0.3, 0.7], [0.7, 0.4, 0.5]]
    for i in range(4):
        for j in range(4):
            shiny = glossy and i < 2
            bsdf = {"type": "roughconductor", "alpha": 0.2} if shiny else \
                _diffuse(colours[(i + j) % 4])
            d[f"wall_{i}_{j}"] = {"type": "rectangle", "bsdf": bsdf,
                                  "to_world": mi.ScalarTransform4f()
                                  .translate([-3.0 + 2.0 * i, -3.0 + 2.0 * j,
                                              3.0 + 0.5 * i + 0.12 * j])
                                  .scale([1.0, 1.0, 1.0]).rotate([0, 1, 0], 180)}
    d["floor"] = {"type": "rectangle", "bsdf": _diffuse([0.45, 0.35, 0.25]),
                  "to_world": mi.ScalarTransform4f().translate([0.0, -1.0, 1.5])
                  .rotate([1, 0, 0], -90).scale([4.0, 1.5, 1.0])}
    return mi.load_dict(d)


def _rendered(scene, first="left", reuse=True):
    integ = FoveatedIntegrator(preset="vr", nested=scene.integrator())
    stereo = Stereo(scene, integ, StereoRig(FRUSTUM, ipd=0.063, width=WIDTH), reuse=reuse,
                    first=first)
    stereo.render((0.45, 0.5), seed=3)
    return stereo


def _borrowed(stereo, eye):
    """The eye's samples that took their value from the other eye (its first frame: no
    history of its own), their film pixels and values."""
    view = stereo.views[eye]
    b = view.buffers
    on = np.array(b["sample_on"], dtype=bool)
    took = on & np.array(b["resampled"], dtype=bool)
    pixels = np.array(b["sample_pixel"], dtype=np.int64)
    values = np.array(b["shading"], dtype=np.float64).reshape(3, -1).T
    return took, pixels, values, on


def _hits(stereo, eye, px, py, du=0.5, dv=0.5):
    """What the rays through film points ``(px + du, py + dv)`` of ``eye`` meet."""
    sensor = stereo.sensors[eye]
    w, h = (int(v) for v in sensor.film().crop_size())
    pos = mi.Point2f(mi.Float((px + du) / w), mi.Float((py + dv) / h))
    ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    return stereo.scene.ray_intersect(ray)


def _seen(stereo, eye, px, py, du=0.5, dv=0.5):
    """What film points ``(px + du, py + dv)`` of ``eye`` see: the albedo (-1 on a miss), the
    hit and the point."""
    si = _hits(stereo, eye, px, py, du, dv)
    ok = si.is_valid()
    a = si.bsdf().eval_diffuse_reflectance(si, ok)
    a = np.array(dr.select(ok, mi.Color3f(a), -1.0), dtype=np.float64).reshape(3, -1).T
    p = np.array(si.p, dtype=np.float64).reshape(3, -1).T
    return a, np.array(ok, dtype=bool), p


def _interior(stereo, eye, px, py):
    """Whether each pixel sees one face across its whole box (its four corners and centre
    agree), and the albedo at its centre."""
    centre, _, _ = _seen(stereo, eye, px, py)
    inside = np.ones(len(px), dtype=bool)
    for du, dv in ((0.01, 0.01), (0.99, 0.01), (0.01, 0.99), (0.99, 0.99)):
        corner, hit, _ = _seen(stereo, eye, px, py, du, dv)
        inside &= hit & np.all(corner == centre, axis=1)
    return inside, centre


@pytest.mark.parametrize("first", EYES)
def test_a_reused_sample_holds_what_tracing_it_gives(first, monkeypatch):
    """Deterministic radiance (the albedo at the hit): a sample whose whole pixel sees one
    face traces that face's albedo, wherever its ray falls in the pixel. A borrowed sample
    whose pixel, and the first eye's sample's pixel, each see one face holds exactly what
    tracing it gives: the plane test never lends it another face's value."""
    from foveated_mi.frame import eye_reuse
    lent = {}
    borrow = eye_reuse.borrow

    def spy(own, history, other, partner):
        lent.update(index=np.array(other.index, dtype=np.int64),
                    pixels=np.array(partner.pixels, dtype=np.int64))
        return borrow(own, history, other, partner)
    monkeypatch.setattr(eye_reuse, "borrow", spy)
    stereo = _rendered(_scene(), first)
    second = "right" if first == "left" else "left"
    took, pixels, values, on = _borrowed(stereo, second)
    w = WIDTH
    inside, centre = _interior(stereo, second, pixels % w, pixels // w)
    source = lent["pixels"][lent["index"]]
    there, _ = _interior(stereo, first, source % w, source // w)
    check = took & inside & there
    # Enough of them to tell: a third of the second eye's samples inside a face, and more
    # (the rest lie at a silhouette in the first eye, or in its crescent).
    assert check.sum() > max(100, (on & inside).sum() / 3), (check.sum(), (on & inside).sum())
    np.testing.assert_array_equal(values[check], centre[check])


def _hidden(stereo, first, second):
    """Whether each of ``second``'s samples sees a point that ``first`` does not: a shadow
    ray from its G-buffer point (a disc pixel's through its centre, a cell's through the
    point it took) to ``first``'s centre meets something."""
    gb = stereo.views[second].planner.samples.gb
    origin = mi.Point3f(*(float(v) for v in
                          np.array(stereo.views[first].planner.history.camera.origin).ravel()))
    d = gb.position - origin
    dist = dr.norm(d)
    ray = mi.Ray3f(origin, d / dist)
    ray.maxt = dist * (1.0 - 1e-4)
    return np.array(gb.hit & stereo.scene.ray_test(ray, gb.hit), dtype=bool)


@pytest.mark.parametrize("first", EYES)
def test_a_point_the_first_eye_did_not_see_is_traced_not_reused(first):
    """The card hides part of the wall from the left eye only: the right eye's pixels there
    (its crescent) are never borrowed, whichever eye goes first; the left eye's crescent
    behind the card, seen from the right eye, likewise. A disc pixel is judged at its
    centre; a cell by the point its ray passes through (that of the first eye it took,
    which need not be its pixel's centre): a cell whose pixel's centre the card hides may
    borrow the point beside it that both eyes see."""
    stereo = _rendered(_scene(), first)
    second = "right" if first == "left" else "left"
    cells = stereo.views[second].history.layout.cells
    took, pixels, _, on = _borrowed(stereo, second)
    hidden = _hidden(stereo, first, second) & on
    assert hidden.sum() >= 5, "the card must hide a part of the wall"
    assert not (took & hidden).any()
    centre = crescent(stereo.eyes, second).ravel()[pixels]
    assert not (took & centre)[cells:].any()
    # What the second eye traced covers every one of its hidden samples.
    traced = np.array(stereo.views[second].buffers["traced"], dtype=bool)
    assert traced[hidden].all()


def test_a_glossy_surface_is_traced_by_both_eyes():
    """A rough conductor's radiance differs between the eyes: none of its samples is reused,
    and the diffuse ones beside it are."""
    stereo = _rendered(_scene(glossy=True))
    took, pixels, _, on = _borrowed(stereo, "right")
    w = WIDTH
    _, hit, p = _seen(stereo, "right", pixels % w, pixels // w)
    # The wall's left half (x < 0, z >= 3) is a rough conductor.
    glossy = hit & (p[:, 0] < 0) & (p[:, 2] > 2.99)
    assert (on & glossy).sum() > 40
    assert not (took & glossy).any()
    assert (took & ~glossy).sum() > 100


def test_the_second_eye_traces_only_what_it_does_not_borrow():
    stereo = _rendered(_scene())
    alone = _rendered(_scene(), reuse=False)
    fraction = {k: s.views["right"].stats["ray_fraction"] for k, s in
                (("reuse", stereo), ("alone", alone))}
    assert fraction["reuse"] < 0.75 * fraction["alone"], fraction
    assert stereo.views["left"].stats["ray_fraction"] == alone.views["left"].stats["ray_fraction"]
    took, _, _, _ = _borrowed(stereo, "right")
    traced = np.array(stereo.views["right"].buffers["traced"], dtype=bool)
    # A borrowed sample is traced only where it shares its pixel with a traced one.
    assert (took & traced).sum() <= 0.05 * took.sum()


#: A symmetric frustum (the eyes' principal points at their films' centres): a point at
#: depth z lies ``FOCAL * ipd / z`` pixels apart in the two films, with no offset between them.
SQUARE = Frustum(40.0, 40.0, 40.0, 40.0)
FOCAL = WIDTH / (2.0 * np.tan(np.radians(40.0)))
IPD = 0.063


def _wall(depth: float):
    """A flat-coloured wall facing the head at ``depth``, half as wide as the view: the sky
    around it (by its edges, traced) keeps the second eye's frame from borrowing all."""
    half = 0.5 * depth * np.tan(np.radians(40.0))
    return mi.load_dict({**_head("test_albedo"),
                         "wall": {"type": "rectangle", "bsdf": _diffuse([0.6, 0.4, 0.2]),
                                  "to_world": mi.ScalarTransform4f().translate([0, 0, depth])
                                  .scale([half, half, 1.0]).rotate([0, 1, 0], 180)}})


def _on_wall(offset: float, reuse=True):
    """Both eyes (symmetric frusta) fixating the wall at the depth where its points lie one
    pixel and ``offset`` apart in the two films: each first-eye pixel centre's point lands
    ``offset`` pixels beside a second-eye pixel's centre (the films' rows agree: the cameras
    are parallel)."""
    scene = _wall(FOCAL * IPD / (1.0 + offset))
    stereo = Stereo(scene, FoveatedIntegrator(preset="vr", nested=scene.integrator()),
                    StereoRig(SQUARE, ipd=IPD, width=WIDTH), reuse=reuse)
    stereo.render((0.5, 0.5), seed=3)
    return stereo


def test_reuse_in_the_periphery_traces_the_second_eye_s_disc():
    stereo = _on_wall(0.0)
    outside = _on_wall(0.0, reuse="periphery")
    cells = stereo.views["right"].history.layout.cells
    for s, disc_borrowed in ((stereo, True), (outside, False)):
        took, _, _, on = _borrowed(s, "right")
        assert took[:cells].sum() > 100
        assert took[cells:].sum() > 20 if disc_borrowed else not took[cells:].any()
        traced = np.array(s.views["right"].buffers["traced"], dtype=bool)
        assert traced[cells:][on[cells:]].all() != disc_borrowed


@pytest.mark.parametrize("offset,borrowed", [(0.0, True), (0.05, True), (0.25, False),
                                             (0.45, False)])
def test_a_disc_pixel_borrows_only_a_point_on_its_centre(offset, borrowed):
    """Each first-eye disc point lands ``offset`` pixels off a second-eye pixel's centre
    (:func:`_on_wall`). The second eye's disc borrows it within an eighth of a pixel of the
    centre (``DISC_REACH``) and traces the rest; anywhere in the pixel (up to half a pixel
    off) its disc would show the first eye's image shifted by up to half a pixel. The cells,
    free to move onto the points (``toward``), borrow whatever the offset."""
    stereo = _on_wall(offset)
    cells = stereo.views["right"].history.layout.cells
    took, _, _, on = _borrowed(stereo, "right")
    disc = on[cells:]
    assert disc.sum() > 20
    traced = np.array(stereo.views["right"].buffers["traced"], dtype=bool)[cells:]
    if borrowed:
        assert took[cells:][disc].mean() > 0.9, took[cells:][disc].mean()
    else:
        assert not took[cells:].any(), took[cells:].sum()
        assert traced[disc].all()
    assert took[:cells].sum() > 100


def test_the_first_eye_is_rendered_as_without_reuse():
    a, b = _rendered(_scene()), _rendered(_scene(), reuse=False)
    np.testing.assert_array_equal(np.array(a.views["left"].buffers["image"]),
                                  np.array(b.views["left"].buffers["image"]))


@pytest.mark.parametrize("kwargs,match", [
    (dict(first="middle"), r"first eye = 'middle' is invalid"),
    (dict(reuse="fovea"), r"reuse = 'fovea' is invalid"),
])
def test_bad_input_gets_one_line(kwargs, match):
    scene = _scene()
    with pytest.raises(ParameterError, match=match) as e:
        Stereo(scene, FoveatedIntegrator(preset="vr", nested=scene.integrator()),
               StereoRig(FRUSTUM, width=32), **kwargs)
    assert "\n" not in str(e.value)


def test_borrow_reads_each_sample_from_one_history_in_one_kernel():
    """Where the other eye's map hits, a sample reads the other eye's value, count and
    second moment; elsewhere its own history's where its own map hits; and all of the reads
    are one kernel: evaluating one evaluates the rest (a timed frame forces them one at a
    time, and each alone would run both maps' gathers again)."""
    from foveated_mi.frame.eye_reuse import borrow
    from foveated_mi.frame.reproject import CameraState, History, ReprojectionMap
    n = 6
    camera = CameraState(mi.Matrix4f(1.0), mi.Point3f(0.0))

    def history(base):
        k = dr.arange(mi.Float, n)
        return History(mean=mi.Color3f(base + k, base + 10 * k, base), count=base + k,
                       moment2=base * k, depth=dr.full(mi.Float, 1.0, n), camera=camera,
                       width=n, height=1)
    own_h, partner = history(100.0), history(200.0)
    i = dr.arange(mi.UInt32, n)
    coords = mi.Point2f(mi.Float(i), 0.0)
    # Lazy maps, as a frame's are: sample k reads the other eye's sample n-1-k on 0 and 1,
    # its own sample k+1 on 1 to 3 (the other eye wins on 1), nothing on 4 and 5.
    other = ReprojectionMap(coords + 0.5, i < 2, (n - 1) - i)
    own = ReprojectionMap(coords, (i >= 1) & (i <= 3), dr.minimum(i + 1, n - 1),
                          dr.full(mi.Bool, True, n))
    m, merged = borrow(own, own_h, other, partner)
    dr.eval(merged.mean)
    for v in (merged.count, merged.moment2, m.hit, m.coords.x):
        assert v.state == dr.VarState.Evaluated
    src = np.array([n - 1, n - 2, 3, 4, 0, 0])
    mine = np.array([True, True, False, False, False, False])
    hit = np.array([True, True, True, True, False, False])
    want = np.where(mine, 200.0 + src, 100.0 + src)
    np.testing.assert_array_equal(np.array(merged.count)[hit], want[hit])
    np.testing.assert_array_equal(np.array(m.hit), hit)
    np.testing.assert_array_equal(np.array(m.index), np.arange(n))


class SkyAlbedo(Albedo):
    """The albedo at the primary hit, the environment's radiance on a miss: deterministic,
    and the same from both eyes for a direction at infinity."""

    def missed(self, scene, si, active):
        return scene.environment().eval(si, active)

    def to_string(self):
        return "SkyAlbedo"


mi.register_integrator("test_sky_albedo", lambda props: SkyAlbedo(props))

#: The sky's radiance falls linearly in elevation, by this much a degree (every channel).
SKY_SLOPE = 0.8 / 180.0


def _sky_scene():
    """The head looks down +z at a floor and a block below the horizon; above it an
    environment map whose radiance is linear in elevation (1.0 at the zenith, 0.2 at the
    nadir), which the map's bilinear lookup reproduces exactly."""
    rows = 181
    ramp = np.linspace(1.0, 0.2, rows, dtype=np.float32)
    sky = np.repeat(ramp[:, None, None], 3, axis=2) * np.ones((rows, 362, 3), np.float32)
    d = {**_head("test_sky_albedo"),
         "sky": {"type": "envmap", "bitmap": mi.Bitmap(sky)},
         "floor": {"type": "rectangle", "bsdf": _diffuse([0.45, 0.35, 0.25]),
                   "to_world": mi.ScalarTransform4f().translate([0.0, -1.0, 4.0])
                   .rotate([1, 0, 0], -90).scale([6.0, 4.0, 1.0])},
         "block": {"type": "cube", "bsdf": _diffuse([0.3, 0.3, 0.7]),
                   "to_world": mi.ScalarTransform4f().translate([0.8, -0.5, 3.0]).scale(0.5)}}
    return mi.load_dict(d)


def _sky_seen(stereo, eye, px, py):
    """The sky's radiance at the centres of ``eye``'s pixels ``(px, py)``."""
    sky = stereo.scene.environment().eval(_hits(stereo, eye, px, py))
    return np.array(mi.Color3f(sky), dtype=np.float64).reshape(3, -1).T


def test_the_sky_is_borrowed_away_from_silhouettes_and_holds_what_tracing_gives():
    """The sky lies at infinity: a second eye's cell in open sky reads the first eye's sample
    of the same direction. Its value is the traced one's within what the sky changes over
    the two samples' rays: each ray lies in its own pixel (a box filter), and the two
    pixels hold one direction (the second eye's cell moved to where the first eye's pixel
    centre's direction lands), so the rays lie at most two pixels apart each way, a
    pixel being at most 80/64 degrees here (the film's centre, the widest). Without the
    margin from silhouettes a borrowed sample here holds the block's or the floor's value
    (0.3 off)."""
    stereo = _rendered(_sky_scene())
    took, pixels, values, on = _borrowed(stereo, "right")
    w = WIDTH
    _, hit, _ = _seen(stereo, "right", pixels % w, pixels // w)
    sky = took & ~hit
    seen = _sky_seen(stereo, "right", pixels % w, pixels // w)
    cells = stereo.views["right"].history.layout.cells
    assert sky[:cells].sum() > 50, sky[:cells].sum()
    bound = SKY_SLOPE * np.hypot(2.0, 2.0) * 80.0 / 64.0
    err = np.abs(values[sky] - seen[sky]).max()
    assert err <= bound, (err, bound)


def test_a_claimed_cell_s_ray_meets_the_first_eye_s_point(monkeypatch):
    """A second eye's cell takes the pixel where one of the first eye's points lands, and
    casts its G-buffer ray through that point's projection, not the pixel's centre: where
    nothing hides the point, the ray meets it (to a thousandth of its distance, where a
    pixel's centre lies up to 0.7 pixel, several thousandths, away), and no shadow ray is
    needed. Nearly all of the claimed cells on a surface meet their point; the cards hide
    the rest."""
    from foveated_mi.frame import eye_reuse
    seen = {}
    same_point = eye_reuse.same_point

    def spy(gb, partner, claimed):
        same = same_point(gb, partner, claimed)
        seen.update(same=np.array(same, dtype=bool),
                    took=np.array(claimed[0] & gb.hit, dtype=bool))
        return same
    monkeypatch.setattr(eye_reuse, "same_point", spy)
    _rendered(_scene())
    took, same = seen["took"], seen["same"]
    assert took.sum() > 100
    assert same.sum() >= 0.9 * took.sum(), (same.sum(), took.sum())
