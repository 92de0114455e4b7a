"""Headset models: each builds, its eye buffer's rays make its frustum's angles, its display's
pixels per degree match the documented table, its lens profile spends the panel's pixels over
its field of view, and a study or the command line puts one eye of it on a scene."""
import math
import os
import re

import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.headsets import HEADSETS, Display, headset, headset_table
from foveated_mi.scenes import load_scene, scene_camera
from foveated_mi.stereo import frustum_of
from foveated_mi.study.spec import parse_study
from foveated_mi.validate import ParameterError

DOCS = os.path.join(os.path.dirname(__file__), os.pardir, "docs", "results.md")
#: The tangent of a float32 ray direction is good to a few ulps; 1e-4 rad is far above it.
ANGLE_RAD = 1e-4


def _documented() -> dict[str, list[str]]:
    """The rows of the headset table in docs/results.md, by headset name."""
    text = open(DOCS, encoding="utf-8").read()
    section = text[text.index("## Headsets"):]
    rows = {}
    for line in section.splitlines()[1:]:
        if line.startswith("## "):
            break
        m = re.match(r"\| `(\w+)` \|(.*)\|$", line)
        if m:
            rows[m.group(1)] = [c.strip() for c in m.group(2).split("|")]
    return rows


@pytest.mark.parametrize("name", sorted(HEADSETS))
def test_each_headset_s_eye_buffer_makes_its_frustum(name):
    h = headset(name)
    rig = h.rig(64)
    for eye in ("left", "right"):
        measured = frustum_of(rig.sensor(mi.ScalarTransform4f(), eye))
        want = rig.realised(eye)
        for side in ("left", "right", "up", "down"):
            assert abs(math.radians(getattr(measured, side) - getattr(want, side))) < ANGLE_RAD
    # The realised vertical angles are within half a pixel of the frustum's.
    tu = math.tan(math.radians(h.frustum.up))
    assert abs(math.tan(math.radians(rig.realised("left").up)) - tu) \
        <= 0.5 * (sum(h.frustum.tangents[:2]) / 64) + 1e-12


@pytest.mark.parametrize("name", sorted(HEADSETS))
def test_the_display_s_centre_ppd_and_frustum_match_the_documented_table(name):
    rows = _documented()
    assert set(rows) == set(HEADSETS), "docs/results.md#headsets lists every headset"
    row = rows[name]
    h = headset(name)
    assert abs(float(row[4]) / h.display.ppd(0.0) - 1.0) <= 0.02
    angles = [float(a) for a in row[1].split("/")]
    assert np.allclose(angles, [h.frustum.left, h.frustum.right, h.frustum.up, h.frustum.down],
                       atol=5e-3)


@pytest.mark.parametrize("name", sorted(HEADSETS))
def test_the_lens_profile_spends_the_panel_s_pixels_over_its_field_of_view(name):
    d = headset(name).display
    e = 0.5 * d.fov_h
    # Trapezoid rule on p(e): exact for the linear profile; for 1/cos^2 its error is
    # h^2 E max|p''| / 12, with 4096 steps below 1e-3 px.
    grid = np.linspace(0.0, e, 4097)
    numeric = np.trapezoid([d.ppd(x) for x in grid], grid)
    assert numeric == pytest.approx(d.pixels_to(e), abs=1e-3)
    if d.kind == "lens":
        assert d.pixels_to(e) == pytest.approx(0.5 * d.panel[0], rel=1e-12)
    else:       # a flat panel spans its pinhole: half its width at half its field of view
        assert d.pixels_to(e) == pytest.approx(0.5 * d.panel[0], rel=2e-4)


def test_a_lens_concentrates_pixels_and_a_pinhole_does_not():
    # Quest 3: 2064 pixels over 94 degrees average 21.96 ppd; 25 at the centre, so fewer at
    # the edge. Varjo XR-4: 51 at the centre of 32 on average.
    for name in ("quest3", "varjo_xr4"):
        d = headset(name).display
        assert d.slope < 0 and d.ppd(0.5 * d.fov_h) < d.panel[0] / d.fov_h < d.ppd(0.0)
    # A pinhole eye buffer has 19 ppd at the centre of Varjo's 3840 pixels over 120 degrees.
    assert headset("varjo_xr4").buffer_ppd() == pytest.approx(
        3840 / (2 * math.tan(math.radians(60))) * math.pi / 180, rel=1e-12)
    assert 19.0 < headset("varjo_xr4").buffer_ppd() < 19.5
    # The viewer resolves the smaller of the two figures.
    h = headset("quest3")
    assert h.viewer_ppd() == min(h.buffer_ppd(), 25.0)
    assert h.viewer_ppd(640) == pytest.approx(h.buffer_ppd(640)) and h.viewer_ppd(640) < 6


@pytest.mark.perceptual
def test_standard_hmd_is_fovvideovdp_s_own_geometry():
    from pyfvvdp.fvvdp_display_model import fvvdp_display_geometry as geometry
    g = geometry((1440, 1600), distance_m=3, fov_diagonal=110)
    h = headset("standard_hmd")
    assert h.display.ppd_centre == pytest.approx(g.ppd_centre, rel=1e-4)
    assert 2 * h.frustum.left == pytest.approx(g.display_size_deg[0], abs=2e-3)
    assert 2 * h.frustum.up == pytest.approx(g.display_size_deg[1], abs=2e-3)
    assert h.buffer_ppd() == pytest.approx(g.ppd_centre, rel=1e-4)


@pytest.mark.parametrize("make, match", [
    (lambda: headset("quest4"), r"headset = 'quest4'.*'quest3'"),
    (lambda: headset("quest3").rig(4), r"eye width = 4"),
    (lambda: Display((100, 100), 90.0, 50.0, 90.0), r"ppd_centre = 50"),
    (lambda: Display((100, 100), 90.0, 1.0, 90.0, "curved"), r"lens kind = 'curved'"),
])
def test_bad_input_gets_one_line(make, match):
    with pytest.raises(ParameterError, match=match) as e:
        make()
    assert "\n" not in str(e.value)


def test_the_documented_table_is_what_the_command_prints():
    text = open(DOCS, encoding="utf-8").read()
    assert headset_table() in text


def _study(viewer: dict, **extra) -> dict:
    return {"size": [64, 64], "scenes": [{"scene": "cornell-box"}], "viewer": viewer,
            "uniform": {"spp": [1]}, **extra}


def test_a_study_headset_sets_each_scene_s_frustum_and_eye_buffer():
    spec = parse_study(_study({"headset": "quest3", "eye_width": 48}))
    scene = spec.scenes[0]
    h = headset("quest3")
    assert scene.size == h.rig(48).size("left")
    assert spec.metrics["viewer"] == "sensor" and spec.perceptual["display"] == "standard_hmd"
    own = scene_camera("cornell-box")
    assert scene.camera["origin"] == own["origin"] and scene.camera["target"] == own["target"]
    # The loaded sensor (the one the references and the frames use) has the eye's frustum.
    loaded = load_scene("cornell-box", width=scene.size[0], height=scene.size[1],
                        camera=scene.camera)
    got, want = frustum_of(loaded.sensors()[0]), h.rig(48).realised("left")
    for side in ("left", "right", "up", "down"):
        assert abs(math.radians(getattr(got, side) - getattr(want, side))) < ANGLE_RAD
    # --size keeps the frustum's aspect: only the width is taken.
    assert spec.with_size((96, 10)).scenes[0].size == h.rig(96).size("left")
    # The Vive Pro's display photometry is FovVideoVDP's model of it.
    assert parse_study(_study({"headset": "htc_vive_pro"})).perceptual["display"] \
        == "htc_vive_pro"


def test_a_study_headset_keeps_the_frustum_along_a_camera_path():
    motion = {"frames": 3, "camera": {"keyframes": [{"t": 0.0, "yaw": 0.0},
                                                    {"t": 0.1, "yaw": 10.0}]}}
    spec = parse_study(_study({"headset": "varjo_xr4", "eye_width": 40}, motion=motion))
    cams = spec.scenes[0].motion["cameras"]
    assert len(cams) == 3 and cams[0]["target"] != cams[2]["target"]
    f = headset("varjo_xr4").frustum
    for cam in cams:
        assert cam["fov"] == pytest.approx(f.fov_x) and cam["principal_point"] == [0.0, 0.0]


def test_a_stereo_study_s_head_looks_straight_ahead_and_its_eyes_gazes_mirror():
    from foveated_mi.stereo import EyeSensors
    motion = {"frames": 2, "camera": {"keyframes": [{"t": 0.0, "yaw": 0.0}]}}
    spec = parse_study(_study({"headset": "quest3", "eye_width": 48, "stereo": True},
                              motion=motion))
    scene = spec.scenes[0]
    rig = headset("quest3").rig(48)
    f, size = rig.head()
    # Centred on the head's axis, each side the eyes' widest (Quest 3: 54° across, 54.27°
    # down), at the eye buffers' pixels per unit tangent.
    assert (f.left, f.right, f.up, f.down) == (54.0, 54.0, 54.27, 54.27)
    assert scene.camera["principal_point"] == [0.0, 0.0] and scene.size == size
    assert all(c["fov"] == pytest.approx(108.0) for c in scene.motion["cameras"])
    loaded = load_scene("cornell-box", width=size[0], height=size[1], camera=scene.camera)
    got = frustum_of(loaded.sensors()[0])
    for side in ("left", "right", "up", "down"):
        assert abs(math.radians(getattr(got, side) - getattr(f, side))) < 0.5 * math.radians(
            108.0) / size[0] + ANGLE_RAD       # the height is whole pixels: half a pixel
    # The head's gaze at its film's centre: the eyes' gazes mirror each other (the fixation
    # lies on the head's mid-plane), within float32 projections.
    (gl, gr), _, hit = EyeSensors(loaded, rig).gazes((0.5, 0.5))
    assert hit
    assert gl[0] + gr[0] == pytest.approx(1.0, abs=1e-5) and gl[1] == pytest.approx(gr[1],
                                                                                     abs=1e-5)
    assert gl[0] > 0.5 > gr[0]      # each eye looks nasally of its film's centre
    # A new width keeps the head centred and the eyes at that width.
    wide = spec.with_size((96, 1)).scenes[0]
    assert wide.size == headset("quest3").rig(96).head()[1]
    assert wide.motion["stereo"]["eye_width"] == 96
    # One eye alone keeps its own off-axis frustum.
    mono = parse_study(_study({"headset": "quest3", "eye_width": 48})).scenes[0]
    assert mono.camera["principal_point"] != [0.0, 0.0]


@pytest.mark.parametrize("viewer, match", [
    ({"headset": "quest4"}, r"viewer.headset"),
    ({"headset": "quest3", "eye_width": 2}, r"viewer.eye_width"),
    ({"fov": "sensor", "eye_width": 64}, r"viewer.eye_width.*headset"),
])
def test_a_study_s_bad_headset_gets_one_line(viewer, match):
    with pytest.raises(ParameterError, match=match) as e:
        parse_study(_study(viewer))
    assert "\n" not in str(e.value)


def test_a_headset_study_sizes_acuity_cells_at_what_the_viewer_resolves():
    data = _study({"headset": "quest3", "eye_width": 64})
    data["foveated"] = {"configs": [
        {"preset": "vr", "polar_cells": "acuity"},
        {"preset": "vr", "polar_cells": "acuity", "viewer_ppd": 30.0},
        {"preset": "vr"}]}
    acuity, given, log = parse_study(data).foveated
    assert acuity["options"]["viewer_ppd"] == pytest.approx(headset("quest3").viewer_ppd(64),
                                                            abs=1e-6)
    assert given["options"]["viewer_ppd"] == 30.0 and log["options"]["viewer_ppd"] == 0.0
