"""The crescents benchmark: each eye's share of pixels the other cannot see."""

BENCH_MODULE = "stereo_crescents"  # the conftest's ``bench`` fixture imports it


def _wall_scene(model, width: int):
    """A wall 2 m ahead, 40 m across: it fills every eye's view."""
    import mitsuba as mi
    from foveated_mi.scenes import sensor_dict
    head = {"origin": [0.0, 0.0, 0.0], "target": [0.0, 0.0, 1.0], "up": [0.0, 1.0, 0.0],
            "fov": 90.0}
    camera, size = model.eye_camera(head, width)
    return mi.load_dict({"type": "scene", "sensor": sensor_dict(camera, width=size[0],
                                                                height=size[1]),
                         "wall": {"type": "rectangle", "to_world": mi.ScalarTransform4f()
                                  .translate([0, 0, 2]).scale([20, 20, 1])}})


def test_an_asymmetric_headset_has_a_crescent_at_each_temporal_edge(bench):
    """Quest 3's eyes see 54 degrees temporally and 40 nasally: on a wall that fills the view
    each eye's temporal band is unseen by the other, its nasal edge seen by both; a symmetric
    headset (standard_hmd) has only the parallax's few columns."""
    from foveated_mi.headsets import headset
    shares = {}
    for name in ("quest3", "standard_hmd"):
        model = headset(name)
        m = bench.measure(_wall_scene(model, 32), model, 32)
        for eye in ("left", "right"):
            assert 0.0 <= m[f"{eye}_near"] <= 1.0 and 0.0 <= m[eye] < 1.0
            # A camera's film runs from its left: the left eye's temporal side is column 0.
            mask = m["masks"][eye]
            temporal, nasal = (mask[:, :3], mask[:, -3:]) if eye == "left" else \
                (mask[:, -3:], mask[:, :3])
            if name == "quest3":
                assert temporal.mean() == 1.0 and nasal.mean() == 0.0
            assert m[f"{eye}_near"] == 0.0       # both eyes see what lies near the gaze
        shares[name] = m["left"]
    assert shares["quest3"] > 4 * shares["standard_hmd"]
