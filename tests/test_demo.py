"""make demo (foveated-mi demo) and the equal-time verdicts it prints."""
import json

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
    sentence = [line for line in text.splitlines() if line.startswith("On voxel-city")]
    assert len(sentence) == 1 and " ms" in sentence[0]
    rows = (out / "results.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 * 2 + 4 - (0 if _oidn() else 2)   # header, fov x frames, uniform
    assert any(p.suffix == ".npy" for p in (out / "references").iterdir())
    # A second run re-renders nothing: same rows, no duplicates.
    assert main(["demo", "--size", "32", "18", "--out", str(out), "--no-progress"]) == 0
    assert (out / "results.csv").read_text().splitlines() == rows


def _oidn():
    from foveated_mi.denoise import oidn_available
    return oidn_available()
