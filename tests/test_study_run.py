"""Studies end to end at 32x32 (issue 10, items 1, 3, 7): local against Dask, resume after a
kill, a dying Dask worker, reference caching, per-frame resume, reference files."""
import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from foveated_mi.metrics import COMPARE_KEYS
from foveated_mi.study import read_rows, run_study
from foveated_mi.study import tasks as T

ROOT = os.path.join(os.path.dirname(__file__), "..")
QUICK = os.path.join(ROOT, "configs", "studies", "quick.toml")
QUALITY = COMPARE_KEYS + ("rays", "ray_fraction", "samples", "history_hit_rate")

TWO = """
description = "two foveated configurations, 32x32"
seed = 3
repeats = 1
warmup = 0
size = [32, 32]
gaze = [0.4, 0.6]
[reference]
spp = 32
[[scenes]]
scene = "cornell-box"
[metrics]
theta = 0.25
[foveated.defaults]
sigma_p = 0.5
theta = 0.2
atrous_iterations = 1
frames = [1, 3]
[foveated.grid]
reconstruction = ["voronoi", "fast_sibson"]
"""

needs_dask = pytest.mark.skipif(
    __import__("importlib").util.find_spec("distributed") is None, reason="dask not installed")


def keyed(path):
    rows = read_rows(path, raw=True)
    return {(r["task_id"], r["frame"]): r for r in rows}, rows


def study_file(tmp_path, text, name="study.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return str(p)


@pytest.mark.slow   # the EXR study below compares local and dask in `make test`
@needs_dask
def test_local_and_dask_give_identical_quality_columns(tmp_path):
    path = study_file(tmp_path, TWO)
    local = run_study(path, out=str(tmp_path / "local"), progress=False, echo=None)
    dask = run_study(path, out=str(tmp_path / "dask"), executor="dask", workers=2,
                     progress=False, echo=None)
    assert local.failed == [] and dask.failed == []
    a, rows_a = keyed(local.results_path)
    b, _ = keyed(dask.results_path)
    assert len(a) == 4 and a.keys() == b.keys()          # 2 configurations x frames 1, 3
    for k in a:
        for col in QUALITY:
            assert a[k][col] == b[k][col], (k, col, a[k][col], b[k][col])   # exact text
    # the reference was rendered once per run, and the two runs agree on it too
    refs = [os.listdir(tmp_path / d / "references") for d in ("local", "dask")]
    assert refs[0] == refs[1] and len(refs[0]) == 2
    npy = [f for f in refs[0] if f.endswith(".npy")][0]
    assert np.array_equal(np.load(tmp_path / "local" / "references" / npy),
                          np.load(tmp_path / "dask" / "references" / npy))
    # sanity of the numbers themselves
    for r in rows_a:
        assert 0 < float(r["ray_fraction"]) < 1 and float(r["time_ms"]) > 0
        assert math.isfinite(float(r["psnr_fovea"])) and 0 <= float(r["flip"]) <= 1


def test_killed_study_resumes_without_duplicates(tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "foveated_mi.cli", "study", QUICK, "--size", "32", "32",
           "--out", str(out), "--no-progress"]
    env = dict(os.environ, FOVEATED_MI_VARIANT="llvm_ad_rgb")
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    results = out / "results.csv"
    deadline = time.time() + 300
    try:
        while time.time() < deadline and proc.poll() is None:
            if results.exists() and results.read_text().count("\n") >= 2:   # header + 1 row
                break
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    before = results.read_text()
    n_before = len(read_rows(results))
    expected = 2 * 2 + 2                   # 2 foveated configs x frames [1, 4] + 2 baselines
    assert 1 <= n_before < expected, "the study finished before it could be killed"
    # a second run finishes the study: every row once, the first run's rows untouched
    rc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    assert rc.returncode == 0, rc.stderr
    after = results.read_text()
    rows = read_rows(results)
    keys = [(r["task_id"], r["frame"]) for r in rows]
    assert len(keys) == len(set(keys)) == expected
    complete = before[: before.rfind("\n") + 1]
    assert after.startswith(complete)
    assert "already done" in rc.stdout


@pytest.mark.slow
@needs_dask
def test_dead_worker_loses_only_its_running_task(tmp_path, monkeypatch):
    """On an existing cluster (--scheduler), a worker process that dies in the middle of a
    task is replaced and the task re-run; every row arrives once."""
    import logging
    from distributed import LocalCluster
    marker = tmp_path / "crashed"
    monkeypatch.setenv(T._CRASH_ONCE_ENV, str(marker))        # inherited by the workers
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.CRITICAL)
    try:
        path = study_file(tmp_path, TWO)
        res = run_study(path, out=str(tmp_path / "out"), executor="dask",
                        scheduler=cluster.scheduler_address, progress=False, echo=None)
    finally:
        cluster.close()
    assert marker.exists(), "no worker died: the hook did not fire"
    assert int(marker.read_text()) != os.getpid()           # a worker, not this process
    assert res.failed == []
    rows = read_rows(res.results_path)
    keys = [(r["task_id"], r["frame"]) for r in rows]
    assert len(keys) == len(set(keys)) == 4


def test_reference_is_cached_and_scenes_load_once(tmp_path):
    out = tmp_path / "out"
    import matplotlib
    backend = matplotlib.get_backend()
    T.clear_scene_cache()
    loads = T.scene_cache_info()["loads"]
    first = run_study(QUICK, out=str(out), size=32, progress=False, echo=None)
    assert matplotlib.get_backend() == backend              # plots never switch the backend
    assert first.references_rendered == 1 and first.tasks_run == 4 and first.new_rows == 6
    assert T.scene_cache_info()["loads"] == loads + 1        # reference + 4 tasks: one load
    ref_dir = out / "references"
    npy = [p for p in ref_dir.iterdir() if p.suffix == ".npy"]
    assert len(npy) == 1 and (ref_dir / (npy[0].stem + ".json")).exists()
    mtime = npy[0].stat().st_mtime_ns
    # same study again: nothing to do
    again = run_study(QUICK, out=str(out), size=32, progress=False, echo=None)
    assert again.references_rendered == 0 and again.tasks_run == 0 and again.new_rows == 0
    assert again.tasks_skipped == 4 and len(again.rows) == 6
    # results removed: the tasks run again but the cached reference is reused as is
    os.remove(first.results_path)
    third = run_study(QUICK, out=str(out), size=32, progress=False, echo=None)
    assert third.references_rendered == 0 and third.new_rows == 6
    assert npy[0].stat().st_mtime_ns == mtime
    a = {(r["task_id"], r["frame"]): r for r in first.rows}
    for r in third.rows:                                     # same seeds: same quality
        assert all(r[c] == a[(r["task_id"], r["frame"])][c] or
                   (math.isnan(r[c]) and math.isnan(a[(r["task_id"], r["frame"])][c]))
                   for c in COMPARE_KEYS)
    # another size is another reference
    other = run_study(QUICK, out=str(out), size=(24, 16), progress=False, echo=None)
    assert other.references_rendered == 1 and len(list(ref_dir.glob("*.npy"))) == 2
    assert {r["width"] for r in other.rows} == {24.0}
    assert os.path.exists(other.png) and os.path.exists(other.svg)
    assert open(other.svg).read().lstrip().startswith("<?xml")


def test_new_frames_resume_per_frame(tmp_path):
    path = study_file(tmp_path, TWO.replace("frames = [1, 3]", "frames = [1]"))
    first = run_study(path, out=str(tmp_path / "o"), progress=False, echo=None)
    assert {r["frame"] for r in first.rows} == {1.0} and first.new_rows == 2
    path = study_file(tmp_path, TWO)
    second = run_study(path, out=str(tmp_path / "o"), progress=False, echo=None)
    assert second.new_rows == 2 and second.tasks_run == 2 and len(second.rows) == 4
    f1 = {r["task_id"]: r for r in second.rows if r["frame"] == 1.0}
    assert {r["task_id"] for r in first.rows} == set(f1)


def test_reference_file_optional_scene_and_missing_oidn(tmp_path, monkeypatch, capsys):
    from foveated_mi import denoise
    ref = np.full((32, 32, 3), 0.25, np.float32)
    np.save(tmp_path / "ref.npy", ref)
    text = TWO.replace("[reference]\nspp = 32", "[reference]\nfile = \"ref.npy\"") + \
        "\n[uniform]\nspp = 1\ndenoise = [false, true]\n" + \
        "[[scenes]]\nscene = \"nowhere/scene.xml\"\noptional = true\n"
    path = study_file(tmp_path, text)
    monkeypatch.setattr(denoise, "oidn_available", lambda: False)
    res = run_study(path, out=str(tmp_path / "o"), progress=False)
    out = capsys.readouterr().out
    assert "scene 'nowhere' skipped" in out and "uniform+oidn baselines skipped" in out
    assert "pip install -e '.[denoise]'" in out
    assert res.references_rendered == 0 and not (tmp_path / "o" / "references").exists()
    assert {r["method"] for r in res.rows} == {"foveated", "uniform"}
    assert {r["scene"] for r in res.rows} == {"cornell-box"}
    # a reference file of the wrong size is bad input
    from foveated_mi import cli
    rc = cli.main(["study", path, "--size", "16", "16", "--out", str(tmp_path / "p"),
                   "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "cornell-box: reference.file = 'ref.npy'" in err


HISTORY = """
seeds = [0, 1]
repeats = 1
warmup = 0
size = [32, 18]
[reference]
spp = 64
[[scenes]]
scene = "cornell-box"
[metrics]
flip = false
[[foveated.configs]]
preset = "guided"
frames = [1, 4]
[uniform]
spp = 1
history = [false, true]
"""


@pytest.mark.parametrize("jod", [False, pytest.param(True, marks=pytest.mark.perceptual)])
def test_uniform_history_rows_seeds_and_jod_column(tmp_path, monkeypatch, capsys, jod):
    from foveated_mi import perceptual
    if not jod:
        monkeypatch.setattr(perceptual, "available", lambda: False)
    res = run_study(study_file(tmp_path, HISTORY), out=str(tmp_path / "o"), progress=False)
    out = capsys.readouterr().out
    assert res.failed == []
    header = open(res.results_path).readline().strip().split(",")
    assert "seed" in header
    assert ("jod" in header) == jod and ("no jod column" in out) == (not jod)
    rows = res.rows
    assert {r["seed"] for r in rows} == {0.0, 1.0}
    hist = [r for r in rows if r["method"] == "uniform+history"]
    # the history baseline is the integrator at sigma_p = 1: every pixel, the preset's frames
    assert sorted((r["seed"], r["frame"]) for r in hist) == [(0, 1), (0, 4), (1, 1), (1, 4)]
    assert all(r["ray_fraction"] == 1.0 and r["sigma_p"] == 1.0 for r in hist)
    assert json.loads(hist[0]["config"])["preset"] == "guided"
    for seed in (0.0, 1.0):        # the history accumulates: frame 4 beats frame 1
        by_frame = {r["frame"]: r for r in hist if r["seed"] == seed}
        assert by_frame[4]["psnr"] > by_frame[1]["psnr"] + 1.0
    plain = [r for r in rows if r["method"] == "uniform"]
    assert [r["frame"] for r in plain] == [1.0, 1.0]
    # Run seed by seed, the second seed's configurations in reverse (results.csv keeps the
    # order the tasks finished in): a drift of the machine's speed does not favour one row.
    ran = list(dict.fromkeys((r["method"], r["seed"]) for r in rows))
    assert ran == [("foveated", 0.0), ("uniform", 0.0), ("uniform+history", 0.0),
                   ("uniform+history", 1.0), ("uniform", 1.0), ("foveated", 1.0)]
    if jod:
        assert all(0.0 < r["jod"] <= 10.0 for r in rows)
        by = {(r["method"], r["frame"], r["seed"]): r["jod"] for r in rows}
        assert by[("uniform+history", 4.0, 0.0)] > by[("uniform+history", 1.0, 0.0)]


EXR_SCENE = """<scene version="3.0.0">
<integrator type="path"><integer name="max_depth" value="3"/></integrator>
<sensor type="perspective"><float name="fov" value="45"/>
<transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
<sampler type="independent"><integer name="sample_count" value="1"/></sampler>
<film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/></film>
</sensor>
<shape type="sphere"><bsdf type="diffuse"/></shape>
<emitter type="envmap"><string name="filename" value="sky.exr"/></emitter>
</scene>"""

EXR_STUDY = """
seed = 1
repeats = 1
warmup = 0
[reference]
spp = 16
[[scenes]]
scene = "{path}"
[foveated.defaults]
atrous_iterations = 1
frames = [1]
[foveated.grid]
reconstruction = ["sibson"]
[uniform]
spp = [1]
"""


@needs_dask
def test_dask_study_of_a_scene_with_an_exr_texture(tmp_path):
    """Loading a scene reads its EXR sky on Dr.Jit's thread pool; a worker given one thread
    used to wait for it forever. Now the study completes, with the local run's quality."""
    import mitsuba as mi
    sky = np.ascontiguousarray(np.linspace(0.2, 2.0, 16 * 8 * 3, dtype=np.float32).reshape(8, 16, 3))
    mi.Bitmap(sky).write(str(tmp_path / "sky.exr"))
    (tmp_path / "scene.xml").write_text(EXR_SCENE)
    path = study_file(tmp_path, EXR_STUDY.format(path=tmp_path / "scene.xml"))
    local = run_study(path, out=str(tmp_path / "local"), progress=False, echo=None)
    dask = run_study(path, out=str(tmp_path / "dask"), executor="dask", workers=2,
                     progress=False, echo=None, task_timeout=120)
    assert local.failed == [] and dask.failed == [], dask.failed
    a, _ = keyed(local.results_path)
    b, _ = keyed(dask.results_path)
    assert len(a) == 2 and a.keys() == b.keys()            # one foveated, one uniform
    # Equal to float precision: Mitsuba's own film (reference, uniform baseline) splats
    # with atomic adds, whose order depends on the worker's thread count.
    for k in a:
        for col in COMPARE_KEYS:
            assert math.isclose(float(a[k][col]), float(b[k][col]), rel_tol=1e-5), \
                (k, col, a[k][col], b[k][col])


@needs_dask
def test_dask_task_that_cannot_finish_fails_after_the_timeout(monkeypatch):
    """A job that sleeps 60 s against a 1 s timeout fails with one line. No clock is read:
    Dask's wait for the next finished job is given the configured timeout (a spy passes it
    on), and without it the job would finish and the test fail."""
    import distributed
    from foveated_mi.study.executors import DaskExecutor
    waits, real_wait = [], distributed.wait

    def wait(fs, **kw):
        waits.append(kw.get("timeout"))
        return real_wait(fs, **kw)

    monkeypatch.setattr(distributed, "wait", wait)
    ex = DaskExecutor(workers=1, task_timeout=1.0)
    try:
        out = list(ex.run([("stuck", time.sleep, (60,))]))
    finally:
        ex.close()
    assert waits == [1.0]
    [(key, result, err)] = out
    assert key == "stuck" and result is None and isinstance(err, TimeoutError)
    assert "within 1 s (--task-timeout)" in str(err) and "\n" not in str(err)


VIEWER = """
seed = 2
repeats = 1
warmup = 0
size = [32, 24]
gaze = [0.4, 0.6]
[reference]
spp = 16
[[scenes]]
scene = "cornell-box"
[viewer]
fov = "sensor"
[metrics]
fovea_deg = {deg}
flip = false
[foveated.defaults]
atrous_iterations = 1
frames = [1]
[foveated.grid]
reconstruction = ["voronoi"]
"""


def test_a_viewer_judges_the_fovea_in_degrees(tmp_path):
    """[viewer] fov = "sensor": the fovea is the pixels within metrics.fovea_deg of the gaze
    ray. 179 degrees holds the whole film (the fovea is the frame, no periphery); a hundredth
    of a degree holds none of it."""
    rows = {}
    for deg in (179.0, 0.01):
        res = run_study(study_file(tmp_path, VIEWER.format(deg=deg), f"v{deg}.toml"),
                        out=str(tmp_path / f"o{deg}"), progress=False, echo=None)
        assert res.failed == []
        [rows[deg]] = read_rows(res.results_path)
    wide, narrow = rows[179.0], rows[0.01]
    assert wide["psnr_fovea"] == pytest.approx(wide["psnr"], rel=1e-12)
    assert math.isnan(wide["psnr_periphery"])
    assert math.isnan(narrow["psnr_fovea"])
    assert narrow["psnr_periphery"] == pytest.approx(narrow["psnr"], rel=1e-12)


@pytest.mark.parametrize("text, key", [
    ('[viewer]\nfov = 0\n', "viewer.fov"),
    ('[viewer]\nfov = "sensor"\nfps = 90\n', "viewer"),
    ('[viewer]\n', "viewer.fov"),
    ('[metrics]\nfovea_deg = 5.0\n', "metrics.fovea_deg"),
    ('[viewer]\nfov = "sensor"\n[metrics]\nfovea_deg = 0\n', "metrics.fovea_deg"),
    ('[viewer]\nfov = "sensor"\ndisplay = ""\n', "viewer.display"),
    ("[motion]\nframes = 1\n", "motion.frames"),
    ("[motion]\nfps = 0\n", "motion.fps"),
    ('[motion]\n[motion.gaze]\ntype = "saccades"\n', "motion.gaze.targets"),
    ("[motion]\nspeed = 3\n", "motion.speed"),
])
def test_bad_viewer_and_motion_tables_are_one_line(tmp_path, text, key):
    from foveated_mi.study import load_study
    from foveated_mi.validate import ParameterError
    base = '[[scenes]]\nscene = "cornell-box"\n[foveated.grid]\nreconstruction = ["voronoi"]\n'
    with pytest.raises(ParameterError) as e:
        load_study(study_file(tmp_path, base + text))
    assert key in str(e.value) and "\n" not in str(e.value), str(e.value)


MOTION = """
seed = 2
repeats = 1
warmup = 0
size = [24, 16]
[reference]
spp = 8
[[scenes]]
scene = "cornell-box"
[viewer]
fov = "sensor"
[motion]
frames = 6
fps = 30
[motion.camera]
[[motion.camera.keyframes]]
t = 0.0
[[motion.camera.keyframes]]
t = 0.2
origin = [0.3, 0.0, 3.9]
[motion.gaze]
type = "saccades"
targets = [[0.3, 0.5], [0.7, 0.4]]
dwell = 0.1
[foveated.defaults]
atrous_iterations = 1
[foveated.grid]
reconstruction = ["voronoi"]
[uniform]
spp = [1]
"""


def _motion_rows(tmp_path, **kw):
    from foveated_mi import perceptual
    res = run_study(study_file(tmp_path, MOTION, "motion.toml"),
                    out=str(tmp_path / kw.get("executor", "local")), progress=False,
                    echo=None, **kw)
    assert res.failed == []
    rows, raw = keyed(res.results_path)
    refs = [np.load(p) for p in (tmp_path / kw.get("executor", "local") / "references"
                                 ).glob("*.npy")]
    return rows, raw, refs, perceptual.available()


def test_a_study_in_motion_scores_sequences(tmp_path):
    """[motion]: one row per sequence (frame = its length), scored against one reference per
    frame of the camera path; the camera goes back where it was for later tasks."""
    from foveated_mi.scenes import camera_of
    from foveated_mi.study.tasks import get_scene
    _, raw, refs, jod = _motion_rows(tmp_path)
    assert sorted(r["method"] for r in raw) == ["foveated", "uniform"]
    assert all(r["frame"] == "6" for r in raw)
    [ref] = refs
    assert ref.shape == (6, 16, 24, 3) and not np.allclose(ref[0], ref[-1])
    assert all(0 < float(r["psnr"]) < math.inf for r in raw)
    assert all(("jod_video" in r and float(r["jod_video"]) <= 10.0) == jod for r in raw)
    # the samples traced, frame by frame (a foveated row's: its rays' at most)
    assert all(0 < float(r["samples"]) <= float(r["rays"]) * float(r["spp"]) for r in raw)
    # the frames after the first: their median, mean and longest
    assert all(0 < float(r["time_ms"]) <= float(r["time_max_ms"])
               and 0 < float(r["time_mean_ms"]) <= float(r["time_max_ms"]) for r in raw)
    parsed = read_rows(str(tmp_path / "local" / "results.csv"))
    assert all(isinstance(r.get("jod_video", 0.0), float) for r in parsed)   # a number column
    from foveated_mi.study import load_study
    scene = get_scene(load_study(str(tmp_path / "motion.toml")).scenes[0].load_spec(),
                      __import__("mitsuba").variant())
    assert camera_of(scene)["origin"] == pytest.approx([0.0, 0.0, 3.9], abs=1e-5)
    # Each row says how its frames ran: timed stage by stage, the foveated frames are
    # traced, like the uniform render; the table compares alike rows and warns of nothing.
    assert {r["trace_mode"] for r in raw} == {"traced"}
    # A row that ran otherwise (here written so by hand) gets one warning in the summary,
    # and the resumed study renders nothing.
    import csv
    path = tmp_path / "local" / "results.csv"
    with open(path, newline="") as f:
        table = list(csv.reader(f))
    table[1][table[0].index("trace_mode")] = "replayed"
    with open(path, "w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(table)
    said = []
    again = run_study(str(tmp_path / "motion.toml"), out=str(tmp_path / "local"),
                      progress=False, echo=said.append)
    assert again.new_rows == 0
    [warning] = again.warnings
    assert "1 replayed, 1 traced" in warning and warning in said


def test_timing_passes_render_each_chosen_sequence_again_unscored(tmp_path, monkeypatch):
    """retime: each chosen sequence row rendered once a pass, every frame, with no scoring;
    its time the median of the passes; the other rows, and every quality column, as
    scored; the camera back where it was."""
    import statistics
    import mitsuba as mi
    from foveated_mi.scenes import camera_of
    from foveated_mi.study import retime as R
    res = run_study(study_file(tmp_path, MOTION, "motion.toml"), out=str(tmp_path / "o"),
                    progress=False, echo=None)
    frames, scored = [], []
    real_renderer = T._sequence_renderer

    def counted(scene, task, gaze):
        render, integ = real_renderer(scene, task, gaze)
        return (lambda g: frames.append(task["method"]) or render(g)), integ
    monkeypatch.setattr(T, "_sequence_renderer", counted)
    monkeypatch.setattr(T, "_quality", lambda *a, **k: scored.append(1))
    done = []
    rows, times = R.retime(res.spec, res.rows, mi.variant(), 2,
                           keep=lambda t: t["method"] == "foveated",
                           progress=lambda d, n: done.append((d, n)))
    assert frames == ["foveated"] * 12 and scored == [] and done == [(1, 2), (2, 2)]
    before = {r["method"]: r for r in res.rows}
    after = {r["method"]: r for r in rows}
    fov = after["foveated"]
    assert len(times[fov["task_id"]]) == 2 and all(t > 0 for t in times[fov["task_id"]])
    assert fov["time_ms"] == statistics.median(times[fov["task_id"]])
    assert fov["time_ms_scored"] == before["foveated"]["time_ms"]
    assert after["uniform"] == before["uniform"] and list(times) == [fov["task_id"]]
    same = lambda x, y: x == y or (x != x and y != y)        # noqa: E731 (nan is nan)
    assert all(same(fov[k], before["foveated"][k]) for k in before["foveated"] if k != "time_ms")
    scene = T.get_scene(res.spec.scenes[0].load_spec(), mi.variant())
    assert camera_of(scene)["origin"] == pytest.approx([0.0, 0.0, 3.9], abs=1e-5)


def test_timing_passes_alternate_their_order_seed_by_seed():
    from foveated_mi.study.retime import retime_order, runs_oidn
    from foveated_mi.validate import ParameterError
    tasks = [{"label": s, "seed": seed, "method": m} for s in ("a", "b") for seed in (0, 1)
             for m in ("foveated", "uniform")]
    got = [(p, t["label"], t["seed"], t["method"][0]) for p, t in retime_order(tasks, 2)]
    assert got == [(0, "a", 0, "f"), (0, "a", 0, "u"), (1, "a", 0, "u"), (1, "a", 0, "f"),
                   (0, "a", 1, "f"), (0, "a", 1, "u"), (1, "a", 1, "u"), (1, "a", 1, "f"),
                   (0, "b", 0, "f"), (0, "b", 0, "u"), (1, "b", 0, "u"), (1, "b", 0, "f"),
                   (0, "b", 1, "f"), (0, "b", 1, "u"), (1, "b", 1, "u"), (1, "b", 1, "f")]
    with pytest.raises(ParameterError) as e:
        retime_order(tasks, 0)
    assert "passes" in str(e.value) and "\n" not in str(e.value)
    assert runs_oidn({"method": "uniform+history+oidn", "options": {}})
    assert runs_oidn({"method": "foveated", "options": {"foveal_disc_denoiser": "oidn"}})
    assert runs_oidn({"method": "foveated", "options": {"preset": "oidn"}})
    # uniform + history: the oidn preset's history, without its denoiser
    assert not runs_oidn({"method": "uniform+history",
                          "options": {"preset": "oidn", "denoiser": "none"}})


def test_a_timing_pass_refuses_what_it_cannot_render():
    from foveated_mi.study.retime import sequence_time
    from foveated_mi.validate import ParameterError
    for motion in (None, {"stereo": {"ipd": 0.063}}):
        with pytest.raises(ParameterError) as e:
            sequence_time({"method": "foveated", "task_id": "x1", "motion": motion})
        assert "x1" in str(e.value) and "one eye" in str(e.value) \
            and "\n" not in str(e.value)


@pytest.mark.slow   # the EXR study above keeps a Dask run in `make test`
@needs_dask
def test_a_study_in_motion_gives_the_same_quality_on_dask(tmp_path):
    a, _, _, _ = _motion_rows(tmp_path)
    b, _, _, _ = _motion_rows(tmp_path, executor="dask", workers=1)
    assert a.keys() == b.keys()
    for k in a:
        for col in COMPARE_KEYS + ("ray_fraction",):
            x, y = float(a[k][col]), float(b[k][col])
            assert (math.isnan(x) and math.isnan(y)) or math.isclose(x, y, rel_tol=1e-5), \
                (k, col, x, y)


def test_a_viewer_sets_the_display():
    from foveated_mi.study import parse_study
    spec = parse_study({"scenes": [{"scene": "cornell-box"}],
                        "viewer": {"fov": "sensor", "display": "standard_hmd"},
                        "foveated": {"grid": {"reconstruction": ["voronoi"]}}})
    assert spec.perceptual["display"] == "standard_hmd" and spec.metrics["viewer"] == "sensor"


def test_a_gaze_path_alone_keeps_one_reference_and_the_camera(tmp_path, monkeypatch):
    """[motion] with a gaze path and no camera path: one reference for every frame, and the
    camera is never read or moved (a sensor that is not perspective will do)."""
    import foveated_mi.scenes as scenes

    def untouchable(*_):
        raise AssertionError("the camera was read or moved")
    monkeypatch.setattr(scenes, "camera_of", untouchable)
    monkeypatch.setattr(scenes, "apply_camera", untouchable)
    camera = MOTION[MOTION.index("[motion.camera]"):MOTION.index("[motion.gaze]")]
    text = MOTION.replace(camera, "")
    assert "[motion.camera]" not in text and "[motion.gaze]" in text
    res = run_study(study_file(tmp_path, text, "gaze.toml"), out=str(tmp_path / "o"),
                    progress=False, echo=None)
    assert res.failed == []
    [ref] = [np.load(p) for p in (tmp_path / "o" / "references").glob("*.npy")]
    assert ref.shape == (16, 24, 3)
    assert all(r["frame"] == 6 for r in read_rows(res.results_path))


def test_a_study_camera_sets_the_field_of_view_and_turns_the_head():
    """camera = { fov, yaw, ... } over the scene's own camera: a headset's field of view for
    any scene; it is part of the scene's identity and of its reference's key, and a study
    without it keeps its ids."""
    import mitsuba as mi
    from foveated_mi import viewer
    from foveated_mi.scenes import scene_camera
    from foveated_mi.study import parse_study
    from foveated_mi.study.tasks import get_scene, reference_key
    base = {"scenes": [{"scene": "cornell-box"}], "size": [24, 16],
            "foveated": {"grid": {"reconstruction": ["voronoi"]}}}
    plain = parse_study(base).scenes[0]
    turned = parse_study({**base, "camera": {"fov": 100.0, "yaw": 30.0}}).scenes[0]
    own = scene_camera("cornell-box")
    assert plain.camera is None and "camera" not in plain.load_spec() \
        and "camera" not in plain.identity()
    assert turned.camera["fov"] == 100.0 and turned.camera["origin"] == own["origin"]
    d0 = np.subtract(own["target"], own["origin"])
    d1 = np.subtract(turned.camera["target"], turned.camera["origin"])
    cos = np.dot(d0, d1) / np.linalg.norm(d0) / np.linalg.norm(d1)
    assert math.degrees(math.acos(cos)) == pytest.approx(30.0, abs=1e-6)
    assert turned.identity()["camera"] == turned.camera
    v = mi.variant()
    assert reference_key(plain, v) != reference_key(turned, v)
    sensor = get_scene(turned.load_spec(), v).sensors()[0]
    # the horizontal field of view across the film's edges (pixel edges, not centres)
    assert viewer.horizontal_fov(sensor) == pytest.approx(100.0, abs=1e-3)
    # a scene's own table wins over the study's
    own_fov = parse_study({**base, "camera": {"fov": 100.0},
                           "scenes": [{"scene": "cornell-box", "camera": {"fov": 60.0}}]})
    assert own_fov.scenes[0].camera["fov"] == 60.0


@pytest.mark.parametrize("text, key", [
    ("camera = { fov = 0 }\n", "camera.fov"),
    ("camera = { yaw = 'left' }\n", "camera.yaw"),
    ("camera = { zoom = 2 }\n", "camera.zoom"),
    ("camera = 100\n", "camera"),
    ('[viewer]\nfov = "sensor"\nmonitor = { ppd = 0 }\n', "viewer.monitor.ppd"),
    ('[viewer]\nfov = "sensor"\nmonitor = { dpi = 3 }\n', "viewer.monitor.dpi"),
    ('[viewer]\nfov = "sensor"\nmonitor = 67\n', "viewer.monitor"),
])
def test_bad_camera_and_monitor_tables_are_one_line(tmp_path, text, key):
    from foveated_mi.study import load_study
    from foveated_mi.validate import ParameterError
    body = '[[scenes]]\nscene = "cornell-box"\n[foveated.grid]\nreconstruction = ["voronoi"]\n'
    top, tables = (text, "") if text.startswith("camera") else ("", text)
    with pytest.raises(ParameterError) as e:
        load_study(study_file(tmp_path, top + body + tables))
    assert f"{key} = " in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_monitor_column_needs_a_monitor(tmp_path):
    from foveated_mi.validate import ParameterError
    text = MOTION.replace("seed = 2\n", 'seed = 2\nmetric = "jod_video_monitor"\n')
    with pytest.raises(ParameterError) as e:
        run_study(study_file(tmp_path, text), out=str(tmp_path / "o"), progress=False,
                  echo=None)
    assert "metric = 'jod_video_monitor'" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.perceptual
def test_a_second_viewing_condition_scores_the_same_frames(tmp_path):
    """[viewer] monitor: the frames a headset row showed are also scored as a video on a
    monitor at 67 ppd (jod_video_monitor), rendered once; the study's columns are what
    perceptual.jod_video gives on those frames under each condition."""
    import mitsuba as mi
    from foveated_mi import perceptual, viewer
    from foveated_mi.study import load_study
    from foveated_mi.study.tasks import expand_tasks, get_scene, run_sequence_task
    text = MOTION.replace('fov = "sensor"\n', 'fov = "sensor"\nmonitor = { ppd = 67.0 }\n')
    path = study_file(tmp_path, text.replace("seed = 2\n",
                                             'seed = 2\nmetric = "jod_video_monitor"\n'))
    res = run_study(path, out=str(tmp_path / "o"), progress=False, echo=None)
    assert res.failed == [] and res.metric == "jod_video_monitor"
    rows = {r["method"]: r for r in read_rows(res.results_path)}
    spec = load_study(path)
    [ref] = [np.load(p) for p in (tmp_path / "o" / "references").glob("*.npy")]
    task = next(t for t in expand_tasks(spec, mi.variant()) if t["method"] == "foveated")
    row, shown = run_sequence_task({**task, "jod": True}, ref)
    refs, tests = np.stack([r for r, _ in shown]), np.stack([t for _, t in shown])
    gazes = spec.scenes[0].motion["gazes"]
    sensor = get_scene(task["scene"], mi.variant()).sensors()[0]
    hmd = perceptual.jod_video(refs, tests, fixations=gazes, fps=30,
                               fov_horizontal=viewer.horizontal_fov(sensor),
                               display=spec.perceptual["display"])
    mon = perceptual.jod_video(refs, tests, fixations=gazes, fps=30, ppd=67.0,
                               display="standard_fhd")
    assert row["jod_video"] == pytest.approx(hmd, abs=1e-6)
    assert row["jod_video_monitor"] == pytest.approx(mon, abs=1e-6)
    assert hmd != pytest.approx(mon, abs=1e-3)           # two conditions, two scores
    # the study's rows come from the same frames (fixed seeds)
    assert rows["foveated"]["jod_video_monitor"] == pytest.approx(mon, abs=1e-4)
    assert all(0.0 < r["jod_video_monitor"] <= 10.0 for r in rows.values())


def test_a_study_in_motion_measures_flicker_per_ring_of_eccentricity(tmp_path):
    """Each sequence row carries the flicker columns, read back as numbers: the temporal
    instability of the frames it showed against their per-frame references, in rings of
    each frame's eccentricity from that frame's gaze (the viewer's geometry, as the fovea
    columns), the periphery outside metrics.fovea_deg."""
    import mitsuba as mi
    from foveated_mi import viewer
    from foveated_mi.metrics import FLICKER_KEYS, temporal_instability
    from foveated_mi.study import load_study
    from foveated_mi.study.tasks import expand_tasks, get_scene, run_sequence_task
    _, _, [ref], _ = _motion_rows(tmp_path)
    rows = {r["method"]: r for r in read_rows(str(tmp_path / "local" / "results.csv"))}
    assert all(isinstance(r[k], float) for r in rows.values() for k in FLICKER_KEYS)
    spec = load_study(str(tmp_path / "motion.toml"))
    gazes = spec.scenes[0].motion["gazes"]
    task = next(t for t in expand_tasks(spec, mi.variant()) if t["method"] == "foveated")
    row, shown = run_sequence_task(task, ref)
    sensor = get_scene(task["scene"], mi.variant()).sensors()[0]
    want = temporal_instability([t for _, t in shown], [r for r, _ in shown],
                                [viewer.eccentricity_map(sensor, g) for g in gazes],
                                fovea_deg=5.0).columns()
    # the same computation on the same frames: equal to the last bit (nan: a ring the film's
    # 39 degrees never reach)
    assert {k: row[k] for k in FLICKER_KEYS} == pytest.approx(want, rel=0, abs=0, nan_ok=True)
    assert math.isnan(want["flicker_35_180"])
    for r in rows.values():
        assert 0.0 < r["flicker_periphery"] < 1.0 and 0.0 < r["flicker_0_5"] < 1.0


def test_a_task_frame_is_the_frame_its_row_was_scored_on(tmp_path):
    """tasks.task_frame (the demo's picture) renders a still task's frame as its row was
    rendered: scored against the cached reference it gives the row's PSNR. A sequence's
    task is refused in one line."""
    import mitsuba as mi
    from foveated_mi.metrics import psnr
    from foveated_mi.render import to_display
    from foveated_mi.study import load_study
    from foveated_mi.study.pictures import cached_reference
    from foveated_mi.study.tasks import expand_tasks, task_frame
    from foveated_mi.validate import ParameterError
    path = study_file(tmp_path, TWO + "[uniform]\nspp = [1]\n")
    res = run_study(path, out=str(tmp_path / "o"), progress=False, echo=None)
    assert res.failed == []
    spec, v = load_study(path), mi.variant()
    ref = to_display(cached_reference(spec, str(tmp_path / "o"), v))
    rows = {(r["task_id"], int(r["frame"])): r for r in read_rows(res.results_path)}
    tasks = expand_tasks(spec, v)
    for t in (tasks[0], tasks[-1]):              # foveated (voronoi), uniform
        frame = max(t["frames"])
        got = psnr(ref, to_display(task_frame(t, frame)), data_range=1.0)
        want = rows[(t["task_id"], frame)]["psnr"]
        # Splatting by atomics may differ between two renders by up to 1e-4 per value
        # (measured on LLVM); the display mapping's steepest slope (sRGB's 12.92) makes that
        # eta = 1.3e-3, and an RMS error moves by at most eta: PSNR within 20 log10(1 +
        # eta / rmse). Frame 1 instead of 3 is 1.1 dB away.
        eta, rmse = 12.92e-4, 10.0 ** (-want / 20.0)
        assert got == pytest.approx(want, abs=20.0 * math.log10(1.0 + eta / rmse)), t["method"]
    motion = load_study(study_file(tmp_path, MOTION, "motion.toml"))
    with pytest.raises(ParameterError) as e:
        task_frame(expand_tasks(motion, v)[0], 6)
    assert str(e.value).startswith("task = ") and "\n" not in str(e.value)


def test_a_tracker_s_latency_renders_earlier_gazes_and_scores_the_true_ones(tmp_path, monkeypatch):
    """[viewer] gaze_latency_ms of one frame: the foveated integrator is given each frame's
    previous gaze, while the metrics fixate the frame's own."""
    from foveated_mi.study import tasks
    given, scored = [], []
    real_renderer, real_viewing = tasks._sequence_renderer, tasks._viewing

    def renderer(scene, task, gaze):
        render, integ = real_renderer(scene, task, gaze)

        def spy(g):
            if integ is not None:
                given.append(list(g))
            return render(g)
        spy.modes = getattr(render, "modes", None)
        return spy, integ

    def viewing(scene, task):
        if task["kind"] == "foveated":
            scored.append(list(task["gaze"]))
        return real_viewing(scene, task)
    monkeypatch.setattr(tasks, "_sequence_renderer", renderer)
    monkeypatch.setattr(tasks, "_viewing", viewing)
    # 100 ms at 30 frames per second: three frames late.
    text = MOTION.replace('[viewer]\nfov = "sensor"\n',
                          '[viewer]\nfov = "sensor"\ngaze_latency_ms = 100.0\n')
    assert "gaze_latency_ms" in text
    res = run_study(study_file(tmp_path, text, "late.toml"), out=str(tmp_path / "out"),
                    progress=False, echo=None)
    assert res.failed == []
    from foveated_mi.study import load_study
    motion = load_study(str(tmp_path / "late.toml")).scenes[0].motion
    shift = round(100.0 * motion["fps"] / 1000.0)
    # With the perceptual extra, the video JOD asks for the viewing once more, at the
    # scene's gaze, after the frames.
    jod = "jod_video" in read_rows(str(tmp_path / "out" / "results.csv"))[0]
    scored = scored[:len(scored) - jod]
    # the scored pass, then the three timing passes, render the same late gazes
    n = len(motion["gazes"])
    assert len(scored) == n and len(given) == 4 * n and shift >= 1
    assert scored == motion["gazes"]
    assert given == [motion["gazes"][max(k - shift, 0)] for k in range(n)] * 4
    assert given[:n] != scored


def test_a_reference_key_follows_the_scene_file_s_content_not_its_time(tmp_path):
    """A remount or a copy that touches the XML keeps its references; an edit renders again."""
    import os
    import mitsuba as mi
    from foveated_mi.study import parse_study
    from foveated_mi.study.tasks import reference_key
    xml = tmp_path / "scene.xml"
    xml.write_text('<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm">'
                   '<integer name="width" value="8"/><integer name="height" value="8"/>'
                   '</film></sensor><emitter type="constant"/></scene>')

    def key():
        spec = parse_study({"scenes": [{"scene": str(xml)}], "size": [8, 8],
                            "foveated": {"grid": {"reconstruction": ["voronoi"]}}})
        return reference_key(spec.scenes[0], mi.variant())
    before = key()
    st = os.stat(xml)
    os.utime(xml, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert key() == before
    xml.write_text(xml.read_text().replace('type="constant"', 'type="constant" id="sky"'))
    assert key() != before


def test_the_timing_order_alternates_each_seed_s_configurations_per_scene():
    from foveated_mi.study.runner import timing_order
    tasks = [{"label": scene, "seed": seed, "row": row}
             for scene in ("a", "b") for row in range(3) for seed in (0, 1, 2)]
    order = timing_order(tasks)
    assert sorted(map(id, order)) == sorted(map(id, tasks))     # every task, once
    got = [(t["label"], t["seed"], t["row"]) for t in order]
    want = [(scene, seed, row) for scene in ("a", "b") for seed in (0, 1, 2)
            for row in ((0, 1, 2) if seed % 2 == 0 else (2, 1, 0))]
    assert got == want
