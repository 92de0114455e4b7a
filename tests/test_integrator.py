"""The `foveated` integrator end to end: loading, wavefront size, equality at sigma_p = 1,
reorder modes, buffers and stats, kernel reuse, determinism, gradients."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.validate import ParameterError


def cornell(w=48, h=40, integrator=None):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=w, height=h, rfilter={"type": "box"})
    d["sensor"]["sampler"]["sample_count"] = 1
    if integrator is not None:
        d["integrator"] = integrator
    return mi.load_dict(d)


class RecordingPath(mi.SamplingIntegrator):
    """Delegates to `path` and records the width of every wavefront it is given."""

    def __init__(self, props=mi.Properties()):
        super().__init__(props)
        self.inner = mi.load_dict({"type": "path", "max_depth": 3})
        self.widths = []

    def sample(self, scene, sampler, ray, medium=None, active=True):
        self.widths.append(dr.width(ray.o.x))
        return self.inner.sample(scene, sampler, ray, medium, active)

    def to_string(self):
        return "RecordingPath"


class DirectionColor(mi.SamplingIntegrator):
    """Deterministic: radiance is a smooth function of the ray direction only."""

    def sample(self, scene, sampler, ray, medium=None, active=True):
        d = ray.d
        return mi.Spectrum(0.5 + 0.5 * d.x, 0.5 + 0.5 * d.y, 0.5 + 0.5 * d.z), mi.Bool(active), []

    def to_string(self):
        return "DirectionColor"


def test_xml_loading_with_unnamed_nested_path():
    scene = mi.load_string("""
    <scene version="3.0.0">
      <integrator type="foveated">
        <float name="theta" value="0.15"/>
        <float name="sigma_p" value="0.7"/>
        <point name="gaze" x="0.25" y="0.75" z="0"/>
        <string name="reorder" value="rows_blocks"/>
        <integrator type="path"><integer name="max_depth" value="3"/></integrator>
      </integrator>
      <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="32"/>
        <integer name="height" value="24"/></film></sensor>
      <shape type="sphere"><bsdf type="diffuse"/></shape>
      <emitter type="constant"/>
    </scene>""")
    integ = scene.integrator()
    assert isinstance(integ, FoveatedIntegrator)
    assert integ.theta == 0.15 and integ.sigma_p == 0.7 and integ.gaze == (0.25, 0.75)
    assert integ.reorder == "rows_blocks"
    assert "max_depth = 3" in str(integ.nested)
    img = mi.render(scene)
    assert img.shape == (24, 32, 3)
    assert np.all(np.isfinite(np.array(img)))


def test_dict_loading_any_nested_key():
    integ = mi.load_dict({"type": "foveated", "theta": 0.2,
                          "whatever_name": {"type": "path", "max_depth": 2}})
    assert "max_depth = 2" in str(integ.nested)
    default = mi.load_dict({"type": "foveated"})
    assert "PathIntegrator" in str(default.nested) or "max_depth" in str(default.nested)


@pytest.mark.parametrize("bad,match", [
    ({"theta": -1.0}, "theta = -1.0 is invalid"),
    ({"sigma_p": 1.5}, "sigma_p = 1.5 is invalid"),
    ({"reorder": "zigzag"}, "reorder = 'zigzag' is invalid"),
    ({"nested": {"type": "ptracer"}}, "nested integrator"),
    ({"nested": {"type": "diffuse"}}, "nested integrator"),
    ({"thetaa": 0.1}, "thetaa"),
])
def test_bad_properties_name_the_parameter(bad, match):
    with pytest.raises(Exception, match=match):
        mi.load_dict({"type": "foveated", **bad})


def test_bad_python_options_one_line():
    with pytest.raises(ParameterError) as e:
        FoveatedIntegrator(gaze=(float("nan"), 0.5))
    assert "gaze" in str(e.value) and "\n" not in str(e.value)
    integ = FoveatedIntegrator()
    before = integ.options
    with pytest.raises(ParameterError):
        integ.theta = 0.0
    assert integ.options == before, "a rejected change must leave the options untouched"


@pytest.mark.parametrize("mode", ["none", "rows", "rows_blocks", "compact"])
def test_nested_sees_the_launch_layout(mode):
    scene = cornell()
    rec = RecordingPath()
    integ = FoveatedIntegrator(nested=rec, theta=0.1, sigma_p=0.3, reorder=mode,
                               atrous_iterations=0)
    mi.render(scene, integrator=integ, spp=3)
    s = integ.stats
    assert rec.widths == [s["lanes_launched"]]
    # The default preset's disc traces 2 of the 3 samples.
    assert s["lanes_active"] == s["rays"] * 3 - s["disc_rays"] and s["rays"] < 48 * 40 // 2
    counts = integ.buffer("sampling_map").sum(1)
    expected = {"none": 48 * 40, "rows": 40 * counts.max(), "compact": s["rays"]}
    if mode in expected:
        assert s["lanes_launched"] == expected[mode] * 3
    else:
        assert s["lanes_active"] <= s["lanes_launched"] <= 40 * counts.max() * 3


@pytest.mark.parametrize("spp", [1, 4])
@pytest.mark.parametrize("mode", ["none", "rows", "rows_blocks", "compact"])
def test_every_pixel_traced_equals_plain_render(spp, mode):
    scene = cornell(integrator={"type": "path", "max_depth": 4})
    plain = np.array(mi.render(scene, spp=spp, seed=7))
    integ = FoveatedIntegrator(preset="paper", nested=scene.integrator(), sigma_p=1.0, reorder=mode,
                               atrous_iterations=0, history=False)
    fov = np.array(mi.render(scene, integrator=integ, spp=spp, seed=7))
    assert integ.stats["rays"] == 48 * 40
    if spp == 1:
        np.testing.assert_array_equal(fov, plain)
    else:  # same random numbers; only the order of the per-pixel sum differs: per side
        # spp - 1 additions of radiance >= 0 (box film: weights 1) and the division (or a
        # product with 1 / spp: 3 roundings with CUDA's approximate reciprocal)
        tolerances.assert_within(fov, plain, tolerances.chain_bound(plain, 2 * (spp + 2)),
                                 mode)


def test_reorder_modes_same_image_with_deterministic_nested():
    scene = cornell()
    imgs = {}
    for mode in ("none", "rows", "rows_blocks", "compact", "tiles"):
        integ = FoveatedIntegrator(preset="paper", nested=DirectionColor(mi.Properties()), theta=0.1,
                                   sigma_p=0.4, reorder=mode, atrous_iterations=0,
                                   reconstruction="voronoi")
        imgs[mode] = np.array(mi.render(scene, integrator=integ, seed=3))
        maps = integ.buffer("sampling_map")
        imgs[mode + "_map"] = maps
    for mode in ("rows", "rows_blocks", "compact", "tiles"):
        np.testing.assert_array_equal(imgs[mode + "_map"], imgs["none_map"])
        # Same pixels, jitter may differ by lane order: direction varies < 1 px apart.
        assert np.abs(imgs[mode] - imgs["none"]).max() < 0.05


def test_buffers_and_stats_after_render():
    integ = FoveatedIntegrator(preset="paper", theta=0.1, sigma_p=0.5, timing=True)
    img = np.array(mi.render(cornell(), integrator=integ, spp=1))
    s = integ.stats
    for key in ("pixels", "rays", "ray_fraction", "timings_ms", "history_hits",
                "history_hit_rate", "resampled", "rejected_samples", "clamped_samples"):
        assert key in s
    assert s["pixels"] == 48 * 40 and 0 < s["ray_fraction"] < 1
    assert set(s["timings_ms"]) == {"gbuffer", "sampling", "reorder", "trace", "reconstruct",
                                   "post", "total"}
    assert all(v >= 0 for v in s["timings_ms"].values())
    smap = integ.buffer("sampling_map")
    assert smap.shape == (40, 48) and smap.sum() == s["rays"]
    near = integ.buffer("nearest")
    assert near.shape == (40, 48, 2)
    # Each pixel's site is a traced pixel.
    xs, ys = near[..., 0].astype(int), near[..., 1].astype(int)
    assert integ.buffer("shading_mask")[ys, xs].all()
    assert np.all(np.isfinite(img)) and img.shape == (40, 48, 3)
    assert not np.any(np.all(img == 0, axis=-1)[integ.buffer("hit").astype(bool)]), "holes left"


# Options a viewer changes from frame to frame; each reaches the kernels through dr.opaque.
PER_FRAME_SCALARS = {
    "gaze": [(0.5, 0.5), (0.3, 0.6), (0.7, 0.2), (0.1, 0.9), (0.55, 0.45), (0.4, 0.4)],
    "theta": [0.1, 0.12, 0.08, 0.2, 0.15, 0.11],
    "sigma_p": [0.6, 0.7, 0.65, 0.5, 0.75, 0.55],
    "exposure": [0.0, 0.5, -1.0, 1.5, -0.25, 2.0],
    "sigma_color": [0.5, 0.4, 0.6, 0.3, 0.7, 0.45],
    "sigma_normal": [0.1, 0.2, 0.15, 0.12, 0.3, 0.25],
    "sigma_position": [0.5, 0.4, 0.6, 0.3, 0.7, 0.45],
    "sigma_luminance": [4.0, 3.0, 5.0, 2.5, 6.0, 4.5],
    "clamp": [1e4, 1e3, 5e3, 2e4, 800.0, 3e3],
    "max_history": [32.0, 16.0, 24.0, 8.0, 20.0, 12.0],
    "reprojection_tolerance": [0.02, 0.03, 0.01, 0.05, 0.025, 0.015],
    "edge_threshold": [0.1, 0.2, 0.15, 0.05, 0.12, 0.3],
    "stochastic_jitter": [4.0, 3.0, 2.0, 5.0, 2.5, 3.5],
}


def _new_kernels_after_warmup(preset, scalars, **options):
    """Kernels launched by frames 3-5 that frames 0-2 did not launch, while ``scalars`` (and
    the seed) change every frame. A kernel is known by its hash (its source): a scalar that
    reaches a kernel as a literal makes a new one per value, even where the kernel cache on
    disk already holds it from an earlier run (so cache hits alone would not tell)."""
    scene = cornell()
    integ = FoveatedIntegrator(preset=preset, sigma_p=0.6, **options)
    seen, new = set(), []
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        for k in range(6):
            integ.set_options(**{name: values[k] for name, values in scalars.items()})
            dr.kernel_history_clear()
            dr.eval(mi.render(scene, integrator=integ, seed=k))
            dr.sync_thread()
            hist = dr.kernel_history([dr.KernelType.JIT])
            assert hist, "kernel history must record the frames"
            hashes = {h["hash"] for h in hist}
            # Warm-up: the first frame, the first with a history, and the first whose
            # history was itself reprojected (its buffers reach the kernels in another
            # order); frame 3 onward launches only kernels seen before.
            if k >= 3:
                new += [h for h in hist if h["hash"] not in seen or not h.get("cache_hit", True)]
            seen |= hashes
    return new


@pytest.mark.parametrize("preset", ["oidn", "paper", "guided"])   # vr: test_kernel_budget
def test_per_frame_scalars_compile_nothing_new(preset):
    """Gaze, theta, seed, exposure, the filters' sigmas, clamp and the history's scalars
    changed on every frame: from frame 3 on, every kernel comes from the cache (on CUDA as
    on LLVM: a Python literal would be a new kernel on both). The launch layout is
    ``compact`` here; the row layouts are the next test."""
    if preset == "oidn":
        pytest.importorskip("pyoidn")
    new = _new_kernels_after_warmup(preset, PER_FRAME_SCALARS, reorder="compact")
    assert not new, f"{len(new)} new kernels after warm-up ({preset})"


def test_per_frame_scalars_compile_nothing_new_in_the_default_vr():
    """The same for the default preset, vr (its launch in tile order), with every scalar that
    it reads; theta, the full-resolution disc's radius, also sets its buffer's grid (a whole
    number of rings and angles), so a new theta is a new buffer, like a new film size."""
    scalars = {k: v for k, v in PER_FRAME_SCALARS.items()
               if k not in ("theta", "edge_threshold", "stochastic_jitter")}
    new = _new_kernels_after_warmup("auto", scalars)
    assert not new, f"{len(new)} new kernels after warm-up (vr)"


@pytest.mark.parametrize("layout", ["rows", "rows_blocks"])
def test_row_layout_launch_compiles_nothing_new(layout):
    new = _new_kernels_after_warmup("paper", {"gaze": PER_FRAME_SCALARS["gaze"]},
                                    reorder=layout)
    assert not new, f"{len(new)} new kernels after warm-up ({layout})"


def test_target_samples_compiles_nothing_new():
    new = _new_kernels_after_warmup("guided", {"target_samples": [32.0, 16.0, 24.0, 8.0, 20.0,
                                                                  12.0]})
    assert not new, f"{len(new)} new kernels after warm-up"


def test_same_seed_is_bit_identical():
    scene = cornell()
    out = []
    for _ in range(2):
        integ = FoveatedIntegrator(theta=0.1, sigma_p=0.5)
        frames = [np.array(mi.render(scene, integrator=integ, seed=5)) for _ in range(3)]
        out.append(frames)
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(out[0][0], out[0][1]), "frames must differ over time"


def test_gradient_pass_leaves_history_unchanged():
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=24, height=20, rfilter={"type": "box"})
    d["integrator"] = {"type": "foveated", "sigma_p": 0.6, "atrous_iterations": 0,
                       "nested": {"type": "path", "max_depth": 2}}
    scene = mi.load_dict(d)
    integ = scene.integrator()
    params = mi.traverse(scene)
    key = "red.reflectance.value"
    mi.render(scene, params, spp=1, seed=0)            # frame 0
    dr.enable_grad(params[key])
    params.update()
    img = mi.render(scene, params, spp=1, seed=1)      # frame 1, primal
    h = integ.history
    snap = (h.mean.numpy().copy(), h.count.numpy().copy(), integ.frame)
    dr.backward(dr.mean(img))                          # gradient pass re-renders
    h2 = integ.history
    assert integ.frame == snap[2] == 2
    np.testing.assert_array_equal(h2.mean.numpy(), snap[0])
    np.testing.assert_array_equal(h2.count.numpy(), snap[1])
    g = dr.grad(params[key])
    assert np.all(np.isfinite(np.array(g))) and np.abs(np.array(g)).sum() > 0


@pytest.mark.parametrize("spp", [1, 4])
def test_paths_are_traced_by_one_kernel(spp):
    scene = cornell()
    integ = FoveatedIntegrator(sigma_p=0.5, atrous_iterations=0, history=False)
    dr.eval(mi.render(scene, integrator=integ, spp=spp))
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        dr.eval(mi.render(scene, integrator=integ, spp=spp))
        dr.sync_thread()
        hist = dr.kernel_history([dr.KernelType.JIT])
    lanes = integ.stats["lanes"]
    heavy = [h for h in hist if h["size"] == lanes and h["operation_count"] > 500]
    assert len(heavy) == 1, [(h["size"], h["operation_count"]) for h in hist]


def test_toggling_history_drops_the_old_history():
    scene = cornell()
    integ = FoveatedIntegrator(sigma_p=0.5, atrous_iterations=0)
    for _ in range(2):
        mi.render(scene, integrator=integ)
    assert integ.history is not None and integ.frame == 2
    integ.history = False
    integ.history = True
    assert integ.history is None and integ.frame == 0


def test_gaze_bound_one_line():
    with pytest.raises(ParameterError, match=r"gaze = .* is invalid: expected two finite"):
        FoveatedIntegrator(gaze=(1e30, 0.5))


def test_setting_the_gaze_validates_and_compiles_nothing_else(monkeypatch):
    """The gaze is a frame's input: ``integ.gaze = ...`` checks it alone (no other option
    validated, no pass's settings compiled) and renders what the same gaze given as an
    option renders; a bad gaze is one line and changes nothing."""
    import foveated_mi.integrators.foveated as module
    scene = cornell()
    a, b = FoveatedIntegrator(preset="vr"), FoveatedIntegrator(preset="vr", gaze=(0.3, 0.6))
    calls = []
    for name in ("validate_options", "frame_settings"):
        real = getattr(module, name)
        monkeypatch.setattr(module, name, lambda *x, real=real, name=name, **k:
                            calls.append(name) or real(*x, **k))
    a.gaze = (0.3, 0.6)
    assert calls == [] and a.gaze == (0.3, 0.6) and a.options["gaze"] == (0.3, 0.6)
    with pytest.raises(ParameterError) as e:
        a.gaze = (float("nan"), 0.5)
    assert str(e.value).startswith("gaze = ") and "\n" not in str(e.value)
    assert a.gaze == (0.3, 0.6)
    img_a = np.array(mi.render(scene, integrator=a, seed=3))
    img_b = np.array(mi.render(scene, integrator=b, seed=3))
    np.testing.assert_array_equal(img_a, img_b)
