"""The benchmarks are one suite: ``python -m benchmarks --list`` lists every module of
benchmarks/, each runs through the runner, and a result carries where and when it was measured
(machine, CPU model, commit, date, variant)."""
import json
import os
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
#: The runner's own files, which are no benchmark.
RUNNER = {"__init__", "__main__", "common"}
#: A benchmark that drives the tests' browser helper, so it puts tests/ on the path.
PATH_USERS = {"bench_live_view"}


def suite_problems(folder: pathlib.Path, suite: dict) -> list[str]:
    """Modules of ``folder`` the suite lacks or lacks a ``main(argv)`` of, names of the suite
    with no module, and modules that patch ``sys.path`` themselves."""
    names = {p.stem for p in folder.glob("*.py")} - RUNNER
    out = [f"{n}: not in the suite" for n in sorted(names - set(suite))]
    out += [f"{n}: no module" for n in sorted(set(suite) - names)]
    for n in sorted(names & set(suite)):
        text = (folder / f"{n}.py").read_text()
        if not re.search(r"^def main\(argv", text, re.M):
            out.append(f"{n}: no main(argv)")
        if n not in PATH_USERS and "sys.path" in text:
            out.append(f"{n}: patches sys.path")
    return out


def test_the_checker_sees_a_stray_script(tmp_path):
    (tmp_path / "a.py").write_text("def main(argv=None):\n    return 0\n")
    (tmp_path / "b.py").write_text("import sys\nsys.path.insert(0, '..')\n")
    assert suite_problems(tmp_path, {"a": "", "c": ""}) == [
        "b: not in the suite", "c: no module"]
    assert suite_problems(tmp_path, {"a": "", "b": ""}) == [
        "b: no main(argv)", "b: patches sys.path"]


def test_benchmarks_holds_the_suite_and_the_list_shows_it():
    from benchmarks.__main__ import SUITE
    assert suite_problems(BENCH, SUITE) == []
    r = subprocess.run([sys.executable, "-m", "benchmarks", "--list"], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert [line.split()[0] for line in r.stdout.splitlines()] == list(SUITE)
    bad = subprocess.run([sys.executable, "-m", "benchmarks", "bench_vr"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "bench_vr" in bad.stderr


def test_a_tiny_run_writes_where_and_when_it_was_measured(tmp_path):
    out = tmp_path / "temporal.json"
    r = subprocess.run([sys.executable, "-m", "benchmarks", "bench_temporal", "--size", "16",
                        "16", "--frames", "2", "--ref-spp", "2", "--out", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=300,
                       env={**os.environ, "FOVEATED_MI_VARIANT": "llvm_ad_rgb"})
    assert r.returncode == 0, r.stderr[-2000:]
    run = json.loads(out.read_text())["run"]
    assert run["cpu_model"] and run["platform"] and run["variant"] == "llvm_ad_rgb"
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT.*", run["date"])
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip()
    assert run["commit"] == (head or None)


#: Only the runner's helpers build a command line, set a variant or write a JSON file.
SHARED = (("ArgumentParser(", "builds its own ArgumentParser (use common.parser)"),
          ("set_variant(", "sets its own variant (use common.setup)"))
#: ``json.dump(`` writes a file; ``json.dumps(`` (a child's or a report's stdout) may stay.
DUMP = re.compile(r"\bjson\.dump\(")


def shared_setup_problems(folder: pathlib.Path, suite: dict) -> list[str]:
    """Modules of the suite in ``folder`` that build their own parser, set their own variant
    or write JSON themselves instead of through ``common``'s ``parser``, ``setup`` and
    ``write_json``, or that do not start from ``common.parser``."""
    out = []
    for n in sorted(suite):
        text = (folder / f"{n}.py").read_text()
        out += [f"{n}: {what}" for needle, what in SHARED if needle in text]
        if DUMP.search(text):
            out.append(f"{n}: writes JSON itself (use common.write_json)")
        if not re.search(r"parser\(__doc__", text):
            out.append(f"{n}: no common.parser(__doc__)")
    return out


def test_the_shared_setup_check_sees_each_stray_case(tmp_path):
    good = ("from common import parser, setup, write_json\n"
            "def main(argv=None):\n    a = parser(__doc__).parse_args(argv)\n    setup(a)\n"
            "    print(json.dumps({}))\n    write_json(a.out, {})\n")
    (tmp_path / "good.py").write_text(good)
    (tmp_path / "bad.py").write_text(
        "import argparse, json, foveated_mi\ndef main(argv=None):\n"
        "    a = argparse.ArgumentParser().parse_args(argv)\n"
        "    foveated_mi.set_variant(a.variant)\n"
        "    with open(a.out, 'w') as f:\n        json.dump({}, f)\n")
    assert shared_setup_problems(tmp_path, {"good": ""}) == []
    assert shared_setup_problems(tmp_path, {"good": "", "bad": ""}) == [
        "bad: builds its own ArgumentParser (use common.parser)",
        "bad: sets its own variant (use common.setup)",
        "bad: writes JSON itself (use common.write_json)",
        "bad: no common.parser(__doc__)"]


def test_every_benchmark_shares_the_parser_the_variant_and_the_output():
    from benchmarks.__main__ import SUITE
    assert shared_setup_problems(BENCH, SUITE) == []


def test_a_benchmark_that_only_printed_writes_the_one_format(tmp_path):
    """peak_memory at 16x16 through the runner: its figures and ``run``; a variant that is
    not available is one line."""
    out = tmp_path / "peak.json"
    env = {**os.environ, "FOVEATED_MI_VARIANT": "llvm_ad_rgb"}
    r = subprocess.run([sys.executable, "-m", "benchmarks", "peak_memory", "--size", "16", "16",
                        "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                       timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    d = json.loads(out.read_text())
    assert d["size"] == [16, 16] and d["finite"] and d["run"]["variant"] == "llvm_ad_rgb"
    bad = subprocess.run([sys.executable, "-m", "benchmarks", "peak_memory", "--variant",
                          "scalar_nope"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                         env=env)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "scalar_nope" in bad.stderr


def test_the_gpu_summary_reads_the_backward_rows(tmp_path):
    """bench_backward writes its rows under ``rows``: the device run's summary lists them."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("_bench_summary",
                                                  ROOT / "scripts" / "_bench_summary.py")
    summary = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(summary)
    (tmp_path / "steps.csv").write_text("step,status,seconds,limit_s,note\n")
    row = {"config": "prb", "size": 64, "primal_ms": 10.0, "step_ms": 30.0,
           "backward_ms": 20.0, "peak_mib": 5.0}
    (tmp_path / "backward_64.json").write_text(json.dumps({"rows": [row], "run": {}}))
    assert "| 64 | prb | 10 | 30 | 20 | 5 |" in summary.summarise(str(tmp_path), "llvm_ad_rgb")
