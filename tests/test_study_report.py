"""``foveated-mi study report`` (foveated_mi.study.report): its rings of eccentricity, its
options and, in the slow tier, a tiny run end to end."""
import json
import math
import os

import numpy as np
import pytest

BENCH_MODULE = "foveated_mi.study.report"  # the conftest's ``bench`` fixture imports it
STUDY = os.path.join(os.path.dirname(__file__), "..", "configs", "studies", "vr.toml")


def test_psnr_by_eccentricity_pools_every_frame_of_a_ring(bench):
    """Two frames; the error is 0.1 within 5 degrees and 0.01 beyond, so the rings' PSNRs are
    20 and 40 dB whatever the gaze; a ring no pixel falls in is nan."""
    h, w = 8, 12
    ref = np.full((h, w, 3), 0.5)
    eccs, shown = [], []
    for gx in (2, 9):
        ecc = np.hypot(np.arange(w)[None, :] - gx, np.arange(h)[:, None] - 4.0)
        err = np.where(ecc < 5.0, 0.1, 0.01)[..., None]
        eccs.append(ecc)
        shown.append((ref, ref + err))
    psnr = bench.eccentricity_psnr(shown, eccs, np.array([0.0, 5.0, 50.0, 60.0]))
    # float64 sums of a few hundred equal squares: far below 1e-9 dB
    assert psnr[:2] == pytest.approx([20.0, 40.0], abs=1e-9) and math.isnan(psnr[2])


def test_the_gaze_ring_marks_only_its_circle():
    from foveated_mi.study.pictures import mark_gaze
    img = np.zeros((40, 60, 3))
    out = mark_gaze(img, (0.5, 0.5), 10)
    ys, xs = np.nonzero(out[..., 0] > 0)
    d = np.hypot(xs + 0.5 - 30, ys + 0.5 - 20)
    assert len(d) > 0 and np.all(np.abs(d - 10) < 1.2) and np.all(img == 0)


def test_unknown_scenes_are_one_line(bench):
    from foveated_mi.validate import ParameterError
    from foveated_mi.config import read_toml
    data = read_toml("study", STUDY)[0]
    args = type("A", (), {"size": None, "frames": None, "seeds": None, "scenes": ["lego"]})
    with pytest.raises(ParameterError) as e:
        bench.overridden(data, args)
    assert "--scenes" in str(e.value) and "voxel-city" in str(e.value) \
        and "\n" not in str(e.value)


@pytest.mark.slow
def test_a_tiny_vr_study_runs_end_to_end(bench, tmp_path):
    res = tmp_path / "res"
    assert bench.main([STUDY, "--size", "32", "18", "--frames", "4", "--seeds", "0", "--scenes",
                       "voxel-city", "--out", str(tmp_path / "vr"), "--results", str(res),
                       "--no-progress"]) == 0
    report = json.loads((res / "vr.json").read_text())
    sps = [s for c in report["conditions"].values() for s in c["speedups"]]
    # every foveated configuration of the study file against each uniform family and their
    # envelope, per condition (without pyoidn, those that need OIDN are left out)
    from foveated_mi.config import read_toml
    from foveated_mi.study.equal_time import envelope_label
    from foveated_mi.denoise import oidn_available
    configs = read_toml("study", STUDY)[0]["foveated"]["configs"]
    if not oidn_available():
        configs = [c for c in configs if "oidn" not in (c.get("preset"), c.get("denoiser"))]
    assert len(sps) == len(report["conditions"]) * len(configs) * \
        ((4 if oidn_available() else 2) + 1)
    assert all(s["family"] in bench.FAMILIES for s in sps if not s["envelope"])
    assert {s["family"] for s in sps if s["envelope"]} == {
        envelope_label(f for f in bench.FAMILIES if any(s["family"] == f for s in sps))}
    assert (res / "vr_eccentricity.png").stat().st_size > 0
    assert (res / "vr_side_by_side.mp4").stat().st_size > 0
    assert "Speed-up at equal" in (res / "vr.md").read_text()
    # the flicker per ring: in the tables and beside the error in the eccentricity picture
    md = (res / "vr.md").read_text()
    assert "## Temporal instability" in md and "| flicker, periphery |" in md
    pics = report["pictures"]
    assert pics["eccentricity_flicker"].keys() == pics["eccentricity_psnr"].keys()
    assert all(len(v) == len(pics["eccentricity_edges_deg"]) - 1
               for v in pics["eccentricity_flicker"].values())
    assert any(x is not None and x > 0 for v in pics["eccentricity_flicker"].values() for x in v)


def _cell_rows():
    """Two seeds of a vr row and a uniform row, with their flicker columns."""
    from foveated_mi.metrics import FLICKER_KEYS
    rows = []
    for seed in (0, 1):
        for method, preset, f in (("foveated", "vr", 0.02), ("uniform", None, 0.01)):
            config = {"options": {"preset": preset}} if preset else {}
            rows.append({"scene": "city", "method": method, "spp": 1.0, "frame": 6.0,
                         "seed": float(seed), "time_ms": 10.0, "ray_fraction": 0.5,
                         "psnr": 30.0, "psnr_fovea": 31.0, "psnr_periphery": 29.0,
                         "config": json.dumps(config),
                         **{k: f * (1 + seed) for k in FLICKER_KEYS},
                         "flicker_35_180": math.nan})
    return rows


def test_the_tables_carry_the_flicker_per_ring(bench):
    """The cells table has the periphery's flicker; the flicker table one column per ring of
    FLICKER_RINGS_DEG, each cell the mean ± standard deviation over seeds, "-" for a ring
    the film never reaches."""
    cells = bench.cells_table(_cell_rows(), ["jod_video"])
    assert cells[0].endswith("| periphery | flicker, periphery | jod_video |")
    assert all(line.count("|") == cells[0].count("|") for line in cells) and len(cells) == 4
    vr = next(line for line in cells if "| vr 1 spp |" in line)
    # seeds 0.02 and 0.04: mean 0.03, sample standard deviation 0.0141
    assert "| 0.0300 ± 0.0141 |" in vr
    table = bench.flicker_table(_cell_rows())
    assert table[0] == ("| scene | configuration | seeds | frame | periphery | 0-5° | 5-10° | "
                        "10-20° | 20-35° | 35+° |")
    vr = next(line for line in table if "| vr 1 spp |" in line)
    uni = next(line for line in table if "| uniform 1 spp |" in line)
    assert vr.count("0.0300 ± 0.0141") == 6 and vr.endswith("| - |")
    assert uni.count("0.0150 ± 0.0071") == 6


def test_flicker_is_held_to_the_uniform_cell_just_above_on_the_envelope(bench):
    """The cheapest uniform cell of any family whose JOD reaches the foveated cell's is the
    one its flicker is held to, ring by ring; within the seeds' spread it is a tie; a
    foveated cell above every uniform cell has none."""
    from foveated_mi.metrics import flicker_ring_columns

    def row(method, spp, seed, jod, ms, periphery, rings, preset=None):
        config = {"options": {"preset": preset}} if preset else {}
        return {"scene": "city", "method": method, "spp": float(spp), "frame": 6.0,
                "seed": float(seed), "time_ms": ms, "jod_video_min": jod,
                "config": json.dumps(config), "flicker": periphery,
                "flicker_periphery": periphery,
                **dict(zip(flicker_ring_columns(), rings))}
    nan = math.nan
    rows = []
    for seed in (0, 1):
        e = 0.001 * seed                      # a spread of 0.0007 between the two seeds
        rows += [
            # The vr cell (JOD 7.0): below, equal, above, a tie and a ring never reached.
            row("foveated", 1, seed, 7.0, 10.0, 0.020, [0.01, 0.03, 0.050 + e, 0.0300, nan],
                "vr"),
            row("foveated", 4, seed, 9.5, 30.0, 0.010, [0.01] * 5, "vr"),
            row("uniform", 1, seed, 6.5, 10.0, 0.001, [0.001] * 5),    # below its JOD
            row("uniform+history", 1, seed, 7.2, 40.0, 0.001, [0.001] * 5),  # dearer
            # Just above on the envelope: the cheapest cell that reaches 7.0.
            row("uniform+oidn", 1, seed, 8.0, 20.0, 0.030,
                [0.02, 0.03, 0.04, 0.0300 + 2 * e, 0.02]),
        ]
    table = bench.flicker_against_envelope(rows, "jod_video_min")
    assert table[0].startswith("| scene | configuration | jod_video_min | the uniform cell "
                               "above it | its jod_video_min | periphery | 0-5° |")
    vr1 = next(line for line in table if "| vr 1 spp |" in line).split(" | ")
    assert vr1[3] == "uniform+oidn 1 spp"
    assert vr1[5:] == ["0.0200 ≤ 0.0300", "0.0100 ≤ 0.0200", "0.0300 ≤ 0.0300",
                       "0.0505 > 0.0400", "0.0300 ≈ 0.0310", "- |"]
    vr4 = next(line for line in table if "| vr 4 spp |" in line)
    assert "none: above every uniform cell" in vr4


def test_the_tables_name_the_eye_buffer_a_headset_sets(bench):
    from foveated_mi.headsets import headset
    w, h = headset("quest3").rig(40).size("left")
    data = {"size": [320, 320], "viewer": {"headset": "quest3", "eye_width": 40}}
    assert bench.film_size(data) == f"{w}x{h}" and (w, h) != (320, 320)
    data["viewer"]["stereo"] = True
    assert bench.film_size(data) == f"{w}x{h} per eye"
    assert bench.film_size({"size": [32, 18]}) == "32x18"


def test_a_headset_stereo_and_tracker_come_from_the_command_line(bench):
    """--headset replaces the study's display by the headset's; --reuse and --first-eye
    say how the eyes render; --one-eye drops a stereo study's second eye; --latency-ms and
    --noise-deg set the tracker; the study parses."""
    from foveated_mi.config import read_toml
    from foveated_mi.study import parse_study
    stereo = os.path.join(os.path.dirname(STUDY), "vr_stereo.toml")
    data = read_toml("study", stereo)[0]
    args = type("A", (), {"size": None, "frames": 2, "seeds": None, "scenes": None,
                          "headset": "htc_vive_pro", "eye_width": 40, "stereo": False,
                          "one_eye": False, "latency_ms": 20.0, "noise_deg": 0.5})
    d = bench.overridden(data, args)
    assert d["viewer"]["headset"] == "htc_vive_pro" and d["viewer"]["eye_width"] == 40
    spec = parse_study(d, base_dir=os.path.dirname(stereo))
    assert spec.perceptual["display"] == "htc_vive_pro"
    motion = spec.scenes[0].motion
    assert motion["stereo"] == {"ipd": 0.063, "headset": "htc_vive_pro", "reuse": True,
                                "first": "left", "eye_width": 40}
    assert motion["gaze_noise_deg"] == 0.5 and "rendered_gazes" in motion
    args.reuse, args.first_eye = "periphery", "right"
    how = parse_study(bench.overridden(data, args), base_dir=os.path.dirname(stereo))
    assert how.scenes[0].motion["stereo"]["reuse"] == "periphery"
    assert how.scenes[0].motion["stereo"]["first"] == "right"
    args.one_eye = True
    one = parse_study(bench.overridden(data, args), base_dir=os.path.dirname(stereo))
    assert "stereo" not in one.scenes[0].motion and one.headset == "htc_vive_pro"
    assert data["viewer"]["stereo"] is True         # the study's own table is left as it was


def test_two_eyes_are_read_against_the_first_eye_alone_at_equal_quality(bench):
    """The one-eye curve is the first eye's time and quality over the foveated rows, read in
    log time at the row's worse eye: a row whose worse eye matches a one-eye point costs
    both eyes' time over that point's; one whose worse eye falls below the curve is a bound."""
    def row(seed, spp, both, left, worse, alone):
        return {"scene": "city", "method": "foveated", "seed": seed, "spp": spp, "frame": 16,
                "config": json.dumps({"options": {"preset": "vr"}, "spp": spp}),
                "time_ms": both, "time_left_ms": left, "time_right_ms": both - left,
                "jod_video_min": worse, "jod_video_left": alone, "ray_fraction": 0.1,
                "trace_mode": "traced"}
    rows = [row(s, 1, 30.0, 17.0, 7.3, 7.3) for s in (0, 1)] + \
        [row(s, 4, 50.0, 28.0, 8.1, 8.1) for s in (0, 1)] + \
        [row(s, 2, 40.0, 22.0, 7.0, 7.7) for s in (0, 1)]
    table = bench.eyes_table(rows, "left", "jod_video_min", "jod_video_left")
    got = {line.split(" | ")[1]: line.split(" | ")[-1] for line in table[2:]}
    assert got["vr 1 spp"].startswith(f"×{30 / 17:.2f} ± 0.00")
    assert got["vr 4 spp"].startswith(f"×{50 / 28:.2f}")
    # 7.0 lies below every one-eye point: one eye reaches it in at most 17 ms.
    assert got["vr 2 spp"].startswith(f"≥×{40 / 17:.2f}")


def test_every_family_is_the_lower_envelope_of_each_family_s_curve(bench):
    """The envelope of every uniform family is never above a family's own curve. The joint
    front of two families can bracket a quality between a cheap cell of one (266 ms, 8.21)
    and a dearer cell of the other (414 ms, 8.23) so that, read between 414 and 440 ms, it
    takes far longer than the first family's own curve (266 to 440 ms, 8.21 to 8.61); and
    where the front is the lower (between the two families' cells), the front counts."""
    def row(method, spp, seed, jod, ms, preset=None):
        config = {"options": {"preset": preset}} if preset else {}
        return {"scene": "city", "method": method, "spp": float(spp), "frame": 6.0,
                "seed": float(seed), "time_ms": ms, "jod_video": jod,
                "config": json.dumps(config)}
    rows = []
    for seed in (0, 1):
        rows += [row("foveated", 4, seed, 8.24, 121.0, "vr"),
                 row("foveated", 1, seed, 8.0, 50.0, "vr"),
                 row("uniform+history", 2, seed, 8.21, 266.0),
                 row("uniform+history", 4, seed, 8.61, 440.0),
                 row("uniform", 1, seed, 7.0, 100.0),
                 row("uniform", 4, seed, 8.23, 414.0)]
    sps = {(s["configuration"], s["family"]): s for s in bench.speedups(rows, "jod_video")}
    envelope = "envelope of uniform and uniform+history"      # the families that ran
    env = sps[("vr 4 spp", envelope)]
    own = sps[("vr 4 spp", "uniform+history")]
    # Its own curve: 266 ms * (440 / 266) ** (0.03 / 0.40), over 121 ms.
    want = 266.0 * (440.0 / 266.0) ** (0.03 / 0.40) / 121.0
    assert own["ratio"] == pytest.approx(want, rel=1e-9)
    assert env["ratio"] == pytest.approx(want, rel=1e-9) and env["relation"] == "="
    assert all(x == pytest.approx(want, rel=1e-9) and r == "=" for x, r in env["per_seed"])
    # At 8.0 the front (100 ms, 7.0 to 266 ms, 8.21) is below the families' own curves
    # (uniform: 100 to 414 ms; uniform + history: its cheapest cell already does, 266 ms).
    front = 100.0 * (266.0 / 100.0) ** (1.0 / 1.21) / 50.0
    assert sps[("vr 1 spp", envelope)]["ratio"] == pytest.approx(front, rel=1e-9)
    assert front < min(sps[("vr 1 spp", f)]["ratio"] for f in ("uniform", "uniform+history"))
    # what sets each point: a family's own curve, or the front between two families' cells
    assert env["set_by"] == "uniform+history 2-4 spp"
    assert sps[("vr 1 spp", envelope)]["set_by"] == \
        "front of uniform 1 spp and uniform+history 2 spp"


def test_the_tables_measure_against_every_family_that_ran_and_name_their_envelope(bench):
    """Dynamic resolution and a flat foveated row are families beside the four uniform ones;
    the envelope is "every uniform family" only with all five kinds, else the families
    named; the table has a column per family, the envelope's and what sets it."""
    def row(method, spp, jod, ms, options=None):
        return {"scene": "city", "method": method, "spp": float(spp), "frame": 6.0,
                "seed": 0.0, "time_ms": ms, "jod_video": jod,
                "config": json.dumps({"options": options or {}})}
    rows = [row("foveated", 1, 7.0, 20.0, {"preset": "vr"}),
            row("foveated", 1, 6.0, 15.0, {"preset": "vr", "sampling_law": "flat"}),
            row("uniform", 1, 5.0, 40.0), row("uniform+oidn", 1, 6.5, 60.0),
            row("uniform+history", 1, 6.0, 50.0), row("uniform+history+oidn", 1, 7.5, 90.0),
            row("uniform@0.5", 1, 4.0, 12.0), row("uniform+oidn@0.5", 1, 6.8, 25.0)]
    sps = bench.speedups(rows, "jod_video")
    fams = ["uniform", "uniform@0.5", "uniform+oidn", "uniform+oidn@0.5", "uniform+history",
            "uniform+history+oidn", "flat vr"]
    envelope = "every uniform family and flat vr"
    assert [s["family"] for s in sps if s["configuration"] == "vr 1 spp"] == fams + [envelope]
    env = next(s for s in sps if s["envelope"] and s["configuration"] == "vr 1 spp")
    # 7.0 lies between OIDN at half scale (25 ms, 6.8) and history + OIDN (90 ms, 7.5)
    assert env["set_by"] == "front of uniform+oidn@0.5 1 spp and uniform+history+oidn 1 spp"
    assert env["ratio"] == pytest.approx(25.0 * 3.6 ** (0.2 / 0.7) / 20.0, rel=1e-12)
    table = bench.speedup_table(sps)
    assert table[0] == ("| scene | configuration | time ms | " + " | ".join(fams)
                        + f" | {envelope} | envelope set by |")
    assert table[2].endswith("| front of uniform+oidn@0.5 1 spp and uniform+history+oidn "
                             "1 spp |")
    # Without dynamic resolution the words "every uniform family" are gone.
    rest = [r for r in rows if "@" not in r["method"]]
    labels = {s["family"] for s in bench.speedups(rest, "jod_video") if s["envelope"]}
    assert labels == {"envelope of uniform, uniform+oidn, uniform+history, "
                      "uniform+history+oidn and flat vr"}


def test_timing_passes_replace_the_times_and_say_so(bench, monkeypatch):
    """--timing-passes: the tables read the rows that retime gives back; the preamble says
    how the times were measured, the report keeps each pass; --timing-skip-oidn keeps the
    scored time of the rows that run OIDN."""
    import argparse
    from foveated_mi.study import retime as R
    seen = {}

    def fake(spec, rows, variant, passes, keep=None, progress=None):
        seen.update(passes=passes, keep=keep)
        return [dict(r, time_ms=1.0) for r in rows], {"t": [1.0, 1.0]}
    monkeypatch.setattr(R, "retime", fake)
    for skip in (False, True):
        a = argparse.Namespace(timing_passes=4, timing_skip_oidn=skip, no_progress=True)
        report = {}
        rows, lines = bench.timed_again(None, [{"time_ms": 9.0}], a, report, ["# t"])
        assert rows == [{"time_ms": 1.0}] and seen["passes"] == 4
        assert lines[0] == "# t" and "rendered 4 more times" in lines[1]
        assert ("keep their scored time" in lines[1]) == skip
        assert report["timing_passes"] == {"passes": 4, "skip_oidn": skip,
                                           "times_ms": {"t": [1.0, 1.0]}}
        if skip:
            assert not seen["keep"]({"method": "uniform+oidn", "options": {}})
            assert seen["keep"]({"method": "uniform+history", "options": {}})
        else:
            assert seen["keep"] is None


def test_a_fixed_foveation_row_is_a_configuration_of_its_own():
    """Rows that differ only in ``eye_tracking`` are two configurations in every table (the
    config column holds it beside the options)."""
    from foveated_mi.study.report import label
    opts = {"preset": "vr", "ray_budget": 0.2}
    tracked = {"method": "foveated", "spp": 2.0, "config": json.dumps({"options": opts})}
    fixed = {**tracked, "config": json.dumps({"options": opts, "eye_tracking": False})}
    assert label(tracked) == "vr 2 spp, ray_budget 0.2"
    assert label(fixed) == "vr 2 spp, ray_budget 0.2, fixed foveation"
