"""The frame driver (foveated_mi.frames): one order of operations for every caller. A fake
view records what the driver asks of it, so each rule here fails if the driver breaks it."""
import pytest

import foveated_mi.scenes as scenes
from foveated_mi.frames import FrameDriver, FrameInput, path_inputs, run_frames
from foveated_mi.validate import ParameterError

CAM_A = {"origin": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "up": [0, 1, 0], "fov": 40.0}
CAM_B = {**CAM_A, "origin": [1.0, 0.0, 5.0]}
HOME = {**CAM_A, "origin": [9.0, 9.0, 9.0]}


class FakeView:
    """Records resets and renders in one log, with the gazes each render was given."""

    def __init__(self, log, two_eyes=False):
        self.log, self.two_eyes = log, two_eyes

    def reset(self):
        self.log.append(("reset",))

    def lens_centre(self):
        return ((0.45, 0.5), (0.55, 0.5)) if self.two_eyes else (0.5, 0.5)

    def render(self, gaze, eye_gazes, seed, spp):
        self.log.append(("render", gaze, eye_gazes, seed, spp))
        return "image", {"seen": gaze}, None


@pytest.fixture
def log(monkeypatch):
    """The shared log; the scene's camera moves are recorded in it instead of made."""
    out = []
    monkeypatch.setattr(scenes, "apply_camera", lambda scene, cam: out.append(("move", cam)))
    monkeypatch.setattr(scenes, "camera_of", lambda scene: HOME)
    return out


def test_a_cut_resets_the_view_before_the_frame_renders(log):
    driver = FrameDriver(None, FakeView(log))
    driver.step(FrameInput(0, gaze=(0.2, 0.3)))
    driver.step(FrameInput(1, cut=True, gaze=(0.2, 0.3), seed=7, spp=2))
    assert log == [("render", (0.2, 0.3), None, 0, 0), ("reset",),
                   ("render", (0.2, 0.3), None, 7, 2)]


def test_the_camera_moves_only_when_it_changes_and_before_the_cut(log):
    driver = FrameDriver(None, FakeView(log), camera=CAM_A)
    inputs = [FrameInput(0, camera=CAM_A, gaze=(0.5, 0.5)),       # where the scene is
              FrameInput(1, camera=CAM_A, gaze=(0.5, 0.5)),       # still
              FrameInput(2, camera=CAM_B, cut=True, gaze=(0.5, 0.5)),
              FrameInput(3, camera=None, gaze=(0.5, 0.5))]        # no camera: stays
    for frame in inputs:
        driver.step(frame)
    kinds = [entry[0] for entry in log]
    assert kinds == ["render", "render", "move", "reset", "render", "render"]
    assert log[2] == ("move", CAM_B)


def test_reapply_moves_to_the_same_camera_after_the_first_frame(log):
    driver = FrameDriver(None, FakeView(log), camera=CAM_A, reapply=True)
    for k in range(3):
        driver.step(FrameInput(k, camera=CAM_A, gaze=(0.5, 0.5)))
    assert [entry[0] for entry in log] == ["render", "move", "render", "move", "render"]


def test_a_path_puts_the_camera_back_however_the_loop_ends(log):
    driver = FrameDriver(None, FakeView(log))
    frames = run_frames(driver, path_inputs([(0.1, 0.2), (0.3, 0.4)], [CAM_A, CAM_B]))
    first = next(frames)
    assert first.input.index == 0 and first.input.camera == CAM_A
    frames.close()                                  # the caller stops after one frame
    assert log == [("move", CAM_A), ("render", (0.1, 0.2), None, 0, 0), ("move", HOME)]
    log.clear()
    list(run_frames(FrameDriver(None, FakeView(log)), path_inputs([(0.1, 0.2)])))
    assert log == [("render", (0.1, 0.2), None, 0, 0)]     # never moved: nothing to restore


def test_fixed_foveation_renders_at_the_lens_centre_and_keeps_the_eye_s_gaze(log):
    driver = FrameDriver(None, FakeView(log), eye_tracking=False)
    frame = driver.step(FrameInput(0, gaze=(0.1, 0.9)))
    assert log == [("render", (0.5, 0.5), None, 0, 0)]
    assert frame.gaze == (0.5, 0.5) and frame.stats == {"seen": (0.5, 0.5)}
    assert frame.input.gaze == (0.1, 0.9)            # the eye's, for the caller's stats


def test_two_eyes_get_their_own_gazes(log):
    eyes = ((0.6, 0.5), (0.4, 0.5))
    FrameDriver(None, FakeView(log, two_eyes=True)).step(
        FrameInput(0, gaze=(0.5, 0.5), eye_gazes=eyes))
    # Fixed foveation: each eye at its own lens centre, whatever the tracker says.
    FrameDriver(None, FakeView(log, two_eyes=True), eye_tracking=False).step(
        FrameInput(1, gaze=(0.5, 0.5), eye_gazes=eyes))
    assert log == [("render", (0.5, 0.5), eyes, 0, 0),
                   ("render", (0.5, 0.5), ((0.45, 0.5), (0.55, 0.5)), 0, 0)]


def test_the_time_is_the_render_s_alone():
    ticks = iter([1.0, 1.25])
    frame = FrameDriver(None, FakeView([]), clock=lambda: next(ticks)).step(
        FrameInput(0, gaze=(0.5, 0.5)))
    assert frame.time_ms == 250.0 and frame.image == "image"


@pytest.mark.parametrize("name", ["eye_tracking", "reapply"])
def test_a_flag_that_is_not_a_bool_is_one_line(name):
    with pytest.raises(ParameterError, match=name):
        FrameDriver(None, FakeView([]), **{name: "yes"})


def test_a_real_frame_through_the_driver_equals_mi_render():
    """A foveated view forces the very image mi.render gives, at the gaze the driver set."""
    import mitsuba as mi
    import numpy as np
    from foveated_mi.frames import FoveatedView
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    scene = scenes.load_scene("cornell-box", width=32, height=24, spp=1)
    integ = FoveatedIntegrator(nested=scene.integrator(), gaze=(0.3, 0.4))
    frame = FrameDriver(scene, FoveatedView(scene, integ)).step(
        FrameInput(0, gaze=(0.3, 0.4), seed=5, spp=1))
    twin = FoveatedIntegrator(nested=scene.integrator(), gaze=(0.3, 0.4))
    expected = np.array(mi.render(scene, integrator=twin, spp=1, seed=5))
    assert isinstance(frame.image, np.ndarray) and frame.image.dtype == np.float32
    np.testing.assert_array_equal(frame.image, expected)
    assert tuple(integ.gaze) == pytest.approx((0.3, 0.4))


def test_the_live_view_renders_through_the_driver(tmp_path):
    """The live view's frame is the driver's step with the mailbox's inputs; switching eye
    tracking off on a running view moves the next frame to the lens centre."""
    from foveated_mi.live.renderer import LiveRenderer
    from foveated_mi.scenes import load_scene
    r = LiveRenderer(load_scene("cornell-box", width=24, height=16),
                     options={"preset": "guided"}, record_dir=str(tmp_path))
    seen, step = [], r.driver.step

    def spy(frame):
        seen.append(frame)
        return step(frame)
    r.driver.step = spy
    r.set_gaze(0.2, 0.3)
    meta = r.render_frame().meta
    assert len(seen) == 1 and seen[0].gaze == (0.2, 0.3) and seen[0].index == 0
    assert seen[0].camera is not None and seen[0].spp == r.spp and seen[0].seed == r.seed
    assert r.integ.gaze == (0.2, 0.3) and meta["frame"] == 0
    r.eye_tracking = False
    r.render_frame()
    assert len(seen) == 2 and seen[1].gaze == (0.2, 0.3)     # the eye's, kept for the page
    assert r.integ.gaze == r.lens_centre and r.driver.eye_tracking is False
