"""make demo (foveated-mi demo) and the equal-time verdicts it prints."""
import json
import math

import numpy as np

import pytest

from foveated_mi.study.equal_time import equal_time_verdicts, verdict_lines, verdict_sentence


def _row(method, spp, frame, time_ms, psnr, fovea, preset=None, **opts):
    config = {"options": {"preset": preset, **opts}} if method == "foveated" else {}
    return {"scene": "s", "method": method, "spp": float(spp), "frame": float(frame),
            "time_ms": time_ms, "psnr": psnr, "psnr_fovea": fovea, "ray_fraction": 0.5,
            "config": json.dumps(config)}


BASE = [_row("uniform", 1, 1, 10.0, 10.0, 10.0), _row("uniform+oidn", 1, 1, 100.0, 30.0, 30.0),
        _row("uniform+oidn", 2, 1, 150.0, 31.0, 31.0)]


def test_verdict_picks_the_best_qualifying_configuration_and_checks_the_targets():
    rows = BASE + [
        _row("foveated", 1, 1, 60.0, 28.0, 31.0, "oidn"), _row("foveated", 1, 16, 60.0, 29.0, 34.5, "oidn"),
        _row("foveated", 2, 1, 90.0, 29.0, 32.0, "oidn"), _row("foveated", 2, 16, 90.0, 30.0, 33.0, "oidn"),
        _row("foveated", 4, 1, 130.0, 35.0, 40.0, "oidn"), _row("foveated", 4, 16, 130.0, 35.0, 40.0, "oidn"),
        _row("foveated", 1, 1, 50.0, 40.0, 40.0, "oidn", theta=0.5),   # not the preset alone
        _row("foveated", 1, 1, 50.0, 40.0, 40.0, "paper")]
    (v,) = equal_time_verdicts(rows, "oidn")
    assert v.baseline["method"] == "uniform+oidn" and v.chosen_spp == 2.0   # 4 spp is too slow
    d = {name: delta for name, delta, _ in v.deltas()}
    assert d["fovea PSNR at frame 1 >= uniform"] == pytest.approx(2.0)
    assert d["fovea PSNR at frame 16 >= uniform + 3 dB"] == pytest.approx(3.0)
    assert d["full-frame PSNR at frame 1 >= uniform - 3 dB"] == pytest.approx(-1.0)
    assert sum("**met**" in line for line in verdict_lines(v)) == 3
    s = verdict_sentence(v)
    assert "gained 2.0 dB" in s and "gained 3.0 dB" in s and "lost 1.0 dB" in s and "90 ms" in s


def test_verdict_says_so_when_nothing_is_as_fast():
    rows = BASE + [_row("foveated", 1, 1, 120.0, 40.0, 40.0, "guided"),
                   _row("foveated", 1, 16, 120.0, 40.0, 40.0, "guided")]
    (v,) = equal_time_verdicts(rows, "guided")
    assert v.chosen is None and v.deltas() == []
    assert "no foveated configuration was as fast" in verdict_sentence(v)
    assert "120 ms" in verdict_sentence(v)


def test_without_a_denoised_baseline_the_raw_uniform_frame_is_the_baseline():
    rows = [BASE[0], _row("foveated", 1, 1, 5.0, 12.0, 9.0, "guided"),
            _row("foveated", 1, 16, 5.0, 13.0, 14.0, "guided")]
    (v,) = equal_time_verdicts(rows, "guided")
    assert v.baseline["method"] == "uniform" and v.chosen_spp == 1.0
    assert "lost 1.0 dB of fovea PSNR on the first frame" in verdict_sentence(v)
    assert "+ OIDN" not in verdict_sentence(v)


def test_demo_runs_end_to_end_and_resumes(tmp_path, capsys):
    from foveated_mi.cli import main
    out = tmp_path / "demo"
    assert main(["demo", "--size", "32", "18", "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "256-spp reference" in text and "foveated (" in text
    # the viewing condition the verdict is judged under: 32 px at 67 ppd span 0.5 degrees
    assert "monitor at 67 pixels per degree: the film spans 0.5° x 0.3°" in text
    sentence = [line for line in text.splitlines() if line.startswith("On voxel-city")]
    assert len(sentence) == 1 and " ms" in sentence[0]
    assert "stronger baseline, uniform 1 spp + history + " in sentence[0]
    assert "means over 3 seeds" in sentence[0] and "uniform+history" in text
    rows = (out / "results.csv").read_text().splitlines()
    # header; per seed: foveated configs x frames, uniform (+ OIDN), with history x frames
    assert len(rows) == 1 + 3 * (2 * 2 + 4 - (0 if _oidn() else 2) + 2 * 2 * 2)
    assert any(p.suffix == ".npy" for p in (out / "references").iterdir())
    # the headset part: a 100-degree camera, vr and the default preset, its own sentence
    assert "In a headset: voxel-city 32x18 through a 100° camera, the film spanning it " \
           "(standard_hmd" in text and "foveated (vr) 4 spp" in text
    head = [line for line in text.splitlines() if line.startswith("In the headset, vr at ")]
    assert len(head) == 1 and "uniform + the same history + " in head[0] and "3 seeds" in head[0]
    # judged on the whole frame (JOD, or full-frame PSNR without the extra), the fovea beside
    from foveated_mi import perceptual
    whole = "over the whole frame" if perceptual.available() else "for full-frame PSNR "
    assert whole in head[0] and "(fovea PSNR " in head[0]
    # vr and uniform at one budget: its sentence, its stats and its labelled picture
    _check_at_budget(out, text)
    _check_side_by_side(out, text)
    hrows = (out / "headset" / "results.csv").read_text().splitlines()
    assert len(hrows) == 1 + 3 * (3 * 2 + 4 - (0 if _oidn() else 2) + 2 * 2 * 2)
    # A second run re-renders nothing: same rows, no duplicates.
    assert main(["demo", "--size", "32", "18", "--out", str(out), "--no-progress"]) == 0
    assert (out / "results.csv").read_text().splitlines() == rows
    assert (out / "headset" / "results.csv").read_text().splitlines() == hrows


def _oidn():
    from foveated_mi.denoise import oidn_available
    return oidn_available()


def _check_at_budget(out, text):
    """Both sides ran at one budget, the uniform 1 spp + history + denoiser frame-16 rows'
    median time; the sentence names it and judges beyond the fovea."""
    import csv
    from foveated_mi import perceptual
    from foveated_mi.demo import BUDGET_FRAMES
    rows = list(csv.DictReader((out / "headset" / "results.csv").open()))
    fam = sorted({r["method"] for r in rows if r["method"].startswith("uniform+history+")})[0]
    budget = float(np.median([float(r["time_ms"]) for r in rows if r["method"] == fam
                              and float(r["spp"]) == 1 and float(r["frame"]) == 16]))
    rec = json.loads((out / "headset" / "at_budget.json").read_text())
    assert rec["budget_ms"] == pytest.approx(budget, rel=1e-12)
    sides = rec["sides"]
    assert "vr (frame_ms)" in sides and rec["compared"] in sides and len(sides) >= 2
    for name, side in sides.items():
        assert len(side["stats"]) == BUDGET_FRAMES, name
        assert all(s["budget_ms"] == rec["budget_ms"] and s["measured_ms"] > 0
                   for s in side["stats"]), name
    assert all("ray_budget" in s for s in sides["vr (frame_ms)"]["stats"])
    assert all(0 < s["scale"] <= 1 for s in sides[rec["compared"]]["stats"])
    [line] = [s for s in text.splitlines() if s.startswith("At one frame budget of ")]
    assert line.startswith(f"At one frame budget of {budget:.0f} ms, vr held ")
    assert f" and {rec['compared']} held " in line
    # what the budget bought: video JOD where the extra runs, and the rings, never the fovea
    # alone (the film spans 100 degrees: every ring out to 35 degrees and beyond has pixels)
    assert ("video JOD" in line) == perceptual.available()
    rings = ["0-5°", "5-10°", "10-20°", "20-35°", "35°+"]
    assert all(f"{r} " in line for r in rings), line
    assert list(sides["vr (frame_ms)"]["rings"]) == rings


def _check_side_by_side(out, text):
    """The demo's picture: a label band over three 32x18 panels, its path printed; the first
    panel is the cached reference in display values with the gaze ringed, the others
    rendered frames, each labelled (the band is the labels' text, drawn on every panel)."""
    import imageio.v3 as iio
    from foveated_mi.render import to_display
    from foveated_mi.study.pictures import LABEL_HEIGHT, RING_COLOUR, label_band, mark_gaze
    png = out / "headset" / "side_by_side.png"
    [line] = [s for s in text.splitlines() if s.startswith("Side by side at one budget (")]
    assert line.endswith(str(png))
    labels = line.split("(", 1)[1].split("; frame ")[0].split(" | ")
    assert labels[0] == "reference (256 spp)" and labels[1].startswith("vr at ")
    assert labels[2].startswith("uniform") and labels[2].endswith(" ms")
    rec = json.loads((out / "headset" / "at_budget.json").read_text())
    assert rec["labels"] == labels
    assert f"picture: {png}" in text
    img = iio.imread(png)
    assert img.shape == (LABEL_HEIGHT + 18, 3 * 32, 3) and img.dtype == np.uint8
    band, img = img[:LABEL_HEIGHT], img[LABEL_HEIGHT:]
    assert np.array_equal(band, label_band(labels, 32))
    for k in range(3):                   # text drawn over every panel, and not the same text
        assert band[:, 32 * k:32 * (k + 1)].any()
    assert not np.array_equal(band[:, 32:64], band[:, 64:96])
    [ref] = [np.load(p) for p in (out / "headset" / "references").glob("*.npy")]
    # 100 degrees over 32 px: 0.3 px per degree, so the 5-degree ring takes its 3-px minimum
    want = (np.clip(mark_gaze(to_display(ref), (0.5, 0.5), 3), 0, 1) * 255 + 0.5).astype(np.uint8)
    assert np.array_equal(img[:, :32], want)
    ring = np.all(img[:, :32] == (np.array(RING_COLOUR) * 255 + 0.5).astype(np.uint8), axis=-1)
    assert 0 < ring.sum() < 32 * 18 // 4
    for k in (1, 2):                     # the same ring on every panel, another image inside
        assert np.array_equal(img[:, 32 * k:32 * (k + 1)][ring], img[:, :32][ring])
        assert not np.array_equal(img[:, 32 * k:32 * (k + 1)], img[:, :32])


def _hist(spp, frame, time_ms, fovea, seed=None, denoiser="oidn", preset="oidn", jod=None):
    method = "uniform+history" + (f"+{denoiser}" if denoiser != "none" else "")
    r = {"scene": "s", "method": method, "spp": float(spp), "frame": float(frame),
         "time_ms": time_ms, "psnr": fovea, "psnr_fovea": fovea, "ray_fraction": 1.0,
         "config": json.dumps({"preset": preset, "full_options": {"denoiser": denoiser}})}
    if seed is not None:
        r["seed"] = float(seed)
    if jod is not None:
        r["jod"] = jod
    return r


def _seeded(row, seed, **kw):
    return {**row, "seed": float(seed), **kw}


def test_frame_16_is_compared_against_uniform_with_the_same_history_and_denoiser():
    rows = BASE + [
        _row("foveated", 2, 1, 90.0, 29.0, 32.0, "oidn"), _row("foveated", 2, 16, 90.0, 30.0, 35.0, "oidn"),
        _hist(1, 1, 110.0, 30.0), _hist(1, 16, 110.0, 34.0),
        _hist(1, 16, 110.0, 40.0, denoiser="svgf", preset="guided"),   # another preset's
        _hist(1, 16, 110.0, 20.0, denoiser="none")]                     # no denoiser
    (v,) = equal_time_verdicts(rows, "oidn")
    assert v.history[16]["psnr_fovea"] == 34.0 and v.chosen_spp == 2.0
    d = {name: delta for name, delta, _ in v.deltas()}
    assert d["fovea PSNR at frame 16 >= uniform with the same history"] == pytest.approx(1.0)
    assert d["fovea PSNR at frame 16 >= uniform + 3 dB"] == pytest.approx(5.0)
    s = verdict_sentence(v)
    assert "stronger baseline, uniform 1 spp + history + oidn at frame 16" in s
    assert "gained 1.0 dB of fovea PSNR" in s


def test_vr_is_compared_against_its_uniform_counterpart_guided():
    """vr's buffer ignores sigma_p, so its uniform rows with history run guided (the same
    history, SVGF); a row labelled vr is not uniform and never the baseline."""
    rows = BASE + [
        _row("foveated", 1, 1, 20.0, 25.0, 32.0, "vr"), _row("foveated", 1, 16, 20.0, 28.0, 35.0, "vr"),
        _hist(1, 1, 60.0, 30.0, denoiser="svgf", preset="guided"),
        _hist(1, 16, 60.0, 33.0, denoiser="svgf", preset="guided"),
        _hist(1, 16, 60.0, 20.0, denoiser="svgf", preset="vr")]
    (v,) = equal_time_verdicts(rows, "vr")
    assert v.history[16]["psnr_fovea"] == 33.0 and v.chosen_spp == 1.0
    d = {name: delta for name, delta, _ in v.deltas()}
    assert d["fovea PSNR at frame 16 >= uniform with the same history"] == pytest.approx(2.0)


def test_seed_means_spreads_and_ties():
    from foveated_mi.study.aggregate import aggregate, margin
    fov = [_row("foveated", 2, f, 90.0, 30.0, 35.0, "oidn") for f in (1, 16)]
    rows = []
    # seeds 0..2: the foveated frame-16 fovea PSNR is 35, 36, 37; the history baseline's
    # 34.5, 35.0, 36.5: a mean margin of +0.67 with per-seed differences 0.5, 1.0, 0.5
    for s, (f16, h16) in enumerate(((35.0, 34.5), (36.0, 35.0), (37.0, 36.5))):
        rows += [_seeded(BASE[1], s), _seeded(fov[0], s),
                 _seeded(fov[1], s, psnr_fovea=f16), _hist(1, 16, 110.0, h16, seed=s)]
    cells = {(c["method"], c["frame"]): c for c in aggregate(rows)}
    c = cells[("foveated", 16.0)]
    assert c["seeds"] == 3 and c["psnr_fovea"] == pytest.approx(36.0)
    assert c["psnr_fovea_sd"] == pytest.approx(1.0)          # sample standard deviation
    assert "seed_sd" not in c and c["spp"] == 2.0            # identity columns untouched
    m = margin(c, cells[("uniform+history+oidn", 16.0)], "psnr_fovea")
    assert m.delta == pytest.approx(2 / 3) and m.seeds == 3
    # the spread is the largest of the cells' spreads (1.0, 1.04) and the differences' (0.29)
    assert m.spread == pytest.approx(np.std([34.5, 35.0, 36.5], ddof=1)) and m.tie
    (v,) = equal_time_verdicts(rows, "oidn")
    lines = verdict_lines(v)
    assert any("same history" in line and "**tie**" in line and "3 seeds" in line
               for line in lines)
    assert "tied (+0.7 ± 1.0 dB" in verdict_sentence(v)
    assert "means over 3 seeds" in verdict_sentence(v)
    # a margin larger than its spread is decided
    wide = [_seeded(r, r["seed"], psnr_fovea=r["psnr_fovea"] + 5.0)
            if r["method"] == "foveated" and r["frame"] == 16 else r for r in rows]
    (v,) = equal_time_verdicts(wide, "oidn")
    m = dict(v.margins())["fovea PSNR at frame 16 >= uniform with the same history"]
    assert not m.tie and m.met and m.delta == pytest.approx(5 + 2 / 3)


def test_speedup_at_equal_quality_interpolates_in_log_time():
    from foveated_mi.study.equal_time import speedup
    fam = [_hist(s, 16, t, 0.0, jod=j) for s, t, j in ((1, 100.0, 8.0), (2, 200.0, 9.0),
                                                        (4, 400.0, 9.5))]
    cell = {"frame": 16.0, "time_ms": 80.0, "jod": 8.5}
    ratio, rel = speedup(cell, fam, "jod")
    assert rel == "=" and ratio == pytest.approx(100 * 2 ** 0.5 / 80)
    assert speedup({**cell, "jod": 9.9}, fam, "jod") == (pytest.approx(5.0), ">")
    assert speedup({**cell, "jod": 7.0}, fam, "jod") == (pytest.approx(1.25), "<")
    assert math.isnan(speedup(cell, fam, "psnr_eccentricity")[0])


def _vr(spp, time_ms, jod, seed):
    return {**_row("foveated", spp, 16, time_ms, 30.0, 30.0, "vr"), "jod": jod,
            "seed": float(seed)}


@pytest.mark.parametrize("time_ms, jod, word", [
    (80.0, 8.5, "foveation paid;"),                               # x1.77 every seed
    (150.0, 8.5, "foveation did not pay at equal quality here;"),  # x0.94
    (80.0, 9.9, "foveation paid;"),                               # never reached: >= x5
    (500.0, 9.9, "never reached it, even in its slowest configuration: no verdict"),
    (80.0, 7.0, "cheapest configuration already does better: no verdict"),
    (120.0, 7.0, "foveation did not pay at equal quality here;"),  # <= x0.83
])
def test_the_headset_sentence_reads_the_speedup_seed_by_seed(time_ms, jod, word):
    """The vr cell at frame 16 against uniform + the same history + OIDN over spp, per seed:
    the family reaches JOD 8 / 9 / 9.5 in 100 / 200 / 400 ms."""
    from foveated_mi.demo import headset_sentence
    from foveated_mi.study.aggregate import aggregate
    rows = []
    for seed in range(3):
        rows.append(_vr(1, time_ms, jod, seed))
        rows += [_hist(s, 16, t, 0.0, seed=seed, jod=q)
                 for s, t, q in ((1, 100.0, 8.0), (2, 200.0, 9.0), (4, 400.0, 9.5))]
    text = headset_sentence(aggregate(rows), "jod")
    assert word in text and "uniform + the same history + OIDN" in text and "3 seeds" in text


def test_the_headset_sentence_names_a_tie_within_the_spread():
    from foveated_mi.demo import headset_sentence
    from foveated_mi.study.aggregate import aggregate
    # per-seed speed-ups 100 * 2 ** f / t: about x0.8, x1.0, x1.3 (a spread over x1)
    rows = [_vr(1, t, 8.0 + f, seed) for seed, (t, f) in enumerate(((125.0, 0.0),
                                                                     (100.0, 0.0),
                                                                     (100.0, 0.4)))]
    rows += [_hist(s, 16, t, 0.0, seed=seed, jod=q) for seed in range(3)
             for s, t, q in ((1, 100.0, 8.0), (2, 200.0, 9.0), (4, 400.0, 9.5))]
    assert "a tie within the spread over seeds" in headset_sentence(aggregate(rows), "jod")


def test_times_of_rows_whose_frames_ran_differently_are_not_compared():
    """A row replayed against a family traced (or the other way) gets no speed-up, seed by
    seed, and no equal-time verdict; rows that ran alike, or rows written before the
    column existed, are compared as before."""
    from foveated_mi.demo import headset_sentence
    from foveated_mi.study.aggregate import aggregate
    from foveated_mi.study.equal_time import (comparable, modes_warning, speedup,
                                              speedup_over_seeds)
    fam = [_hist(s, 16, t, 0.0, jod=j) for s, t, j in ((1, 100.0, 8.0), (2, 200.0, 9.0),
                                                        (4, 400.0, 9.5))]
    cell = {"frame": 16.0, "time_ms": 80.0, "jod": 8.5}
    traced = [{**r, "trace_mode": "traced"} for r in fam]
    assert speedup(cell, traced, "jod")[1] == "="                    # no column on the cell
    assert speedup({**cell, "trace_mode": "traced"}, traced, "jod")[1] == "="
    ratio, rel = speedup({**cell, "trace_mode": "replayed"}, traced, "jod")
    assert math.isnan(ratio) and rel == "≠"
    assert not comparable([{**cell, "trace_mode": "replayed"}, *traced])
    rows = []
    for seed in range(3):
        rows.append({**_vr(1, 80.0, 8.5, seed), "trace_mode": "replayed"})
        rows += [{**_hist(s, 16, t, 0.0, seed=seed, jod=q), "trace_mode": "traced"}
                 for s, t, q in ((1, 100.0, 8.0), (2, 200.0, 9.0), (4, 400.0, 9.5))]
    cells = aggregate(rows)
    vr = next(c for c in cells if c["method"] == "foveated")
    s = speedup_over_seeds(vr, [c for c in cells if c is not vr], "jod")
    assert s.refused and all(r == "≠" for _, r in s.per_seed) and "refused" in s.text()
    assert "replayed against traced: no verdict" in headset_sentence(cells, "jod")
    line = modes_warning(rows, "scene cbox")
    assert line is not None and "3 replayed, 9 traced" in line and "\n" not in line
    assert modes_warning([r for r in rows if r["trace_mode"] == "traced"], "x") is None


def test_an_equal_time_verdict_refuses_a_candidate_that_ran_otherwise():
    rows = [{**r, "trace_mode": "traced"} for r in BASE + [
        _row("foveated", 1, 1, 60.0, 28.0, 31.0, "oidn"),
        _row("foveated", 1, 16, 60.0, 29.0, 34.5, "oidn")]]
    (v,) = equal_time_verdicts(rows, "oidn")
    assert v.chosen is not None and not v.refused
    replayed = [{**r, "trace_mode": "replayed"} if r["method"] == "foveated" else r
                for r in rows]
    (v,) = equal_time_verdicts(replayed, "oidn")
    assert v.chosen is None and v.refused
    assert any("Not compared" in line for line in verdict_lines(v))


def _psnr_rows(vr_psnr, vr_fovea, seeds=3):
    """A vr cell at frame 16 and uniform + the same history + OIDN at 1, 2 and 4 spp, whose
    fovea PSNR is far below its full-frame PSNR (as a denoised frame's can be in a headset)."""
    rows = []
    for seed in range(seeds):
        rows.append({**_row("foveated", 4, 16, 40.0, vr_psnr, vr_fovea, "vr"),
                     "seed": float(seed)})
        rows += [{**_hist(s, 16, t, 0.0, seed=seed), "psnr": p, "psnr_fovea": p - 6.0}
                 for s, t, p in ((1, 100.0, 30.0), (2, 200.0, 32.0), (4, 400.0, 34.0))]
    return rows


def test_the_headset_sentence_without_jod_judges_the_whole_frame():
    """Without the perceptual extra the sentence reads full-frame PSNR: a vr frame whose
    fovea beats every baseline cell but whose whole frame is below the cheapest one is no
    win, and the sentence says which figure it judged, the fovea's only beside it."""
    from foveated_mi.demo import headset_sentence
    from foveated_mi.study.aggregate import aggregate
    cells = aggregate(_psnr_rows(vr_psnr=27.0, vr_fovea=35.0))
    text = headset_sentence(cells, "psnr")
    assert "for full-frame PSNR 27.00 dB (fovea PSNR 35.00 dB)" in text
    assert "for the same full-frame PSNR" in text and "foveation paid" not in text
    assert "cheapest configuration already does better: no verdict" in text
    # judged by the fovea alone the same cells would have read as a win
    assert "foveation paid" in headset_sentence(cells, "psnr_fovea")
    # 31 dB over the whole frame, halfway from 30 to 32 dB in log time: 100 * 2 ** 0.5 ms
    # against 40 ms, the same on every seed; a fovea far below the baseline's changes nothing
    text = headset_sentence(aggregate(_psnr_rows(vr_psnr=31.0, vr_fovea=20.0)), "psnr")
    assert "needs ×3.54 ± 0.00 that time for the same full-frame PSNR (foveation paid;" in text


def test_ring_psnr_pools_each_ring_s_errors_over_the_frames():
    from foveated_mi.demo import ring_psnr
    ecc = np.tile(np.arange(8, dtype=np.float64) * 6.0, (4, 1))     # 0, 6, ..., 42 degrees
    ref = np.full((4, 8, 3), 0.5)
    err = np.where(ecc < 5, 0.1, np.where(ecc < 20, 0.01, 0.001))[..., None]
    frames = np.stack([ref + err, ref - err])
    out = ring_psnr(ref, frames, ecc)
    assert list(out) == ["0-5°", "5-10°", "10-20°", "20-35°", "35°+"]
    # PSNR = 10 log10(1 / e^2) for a constant error e, to float64 rounding
    np.testing.assert_allclose(list(out.values()), [20.0, 40.0, 40.0, 60.0, 60.0], rtol=1e-12)
    with pytest.raises(Exception) as e:
        ring_psnr(ref, frames[0], ecc)
    assert "frames" in str(e.value) and "\n" not in str(e.value)


def test_the_budget_sentence_reads_jod_and_every_ring_never_the_fovea_alone():
    from foveated_mi.demo import budget_sentence
    rings = {"0-5°": 30.0, "5-10°": 28.0, "35°+": 25.0}
    fig = {"vr": {"held_ms": 50.0, "chose": "2 spp at 20% of the rays", "rings": rings},
           "u": {"held_ms": 52.0, "chose": "1 spp at render scale 0.71",
                 "rings": {k: v - 2.0 + (k == "35°+") * 3.0 for k, v in rings.items()}}}
    text = budget_sentence(55.0, "vr", "u", fig, 0)
    assert text.startswith("At one frame budget of 55 ms, vr held 50 ms (2 spp at 20% of the "
                           "rays) and u held 52 ms (1 spp at render scale 0.71)")
    assert "PSNR ring by ring of eccentricity 0-5° +2.0 dB, 5-10° +2.0 dB, 35°+ -1.0 dB" \
        in text
    assert "JOD" not in text
    fig["vr"]["jod"], fig["u"]["jod"] = 8.1, 7.6
    assert "+0.50 video JOD (8.10 against 7.60) and, ring by ring of eccentricity, PSNR 0-5° " \
        "+2.0 dB" in budget_sentence(55.0, "vr", "u", fig, 0)
