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
