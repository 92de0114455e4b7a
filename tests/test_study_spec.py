"""Study files: schema validation (one line, exit 2), grid expansion, results.csv repair and
Pareto fronts on hand-made points. No rendering here."""
import math
import os
import sys
import textwrap

import pytest

from foveated_mi import cli
from foveated_mi.study import load_study, pareto_front, scene_fronts
from foveated_mi.study import results as R
from foveated_mi.study.tasks import expand_tasks
from foveated_mi.validate import ParameterError

QUICK = os.path.join(os.path.dirname(__file__), "..", "configs", "studies", "quick.toml")

BASE = """
seed = 0
size = [16, 16]
[[scenes]]
scene = "cornell-box"
[foveated.grid]
theta = [0.1, 0.2]
"""


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return str(p)


# ---------------------------------------------------------------------------------------------
# schema
# ---------------------------------------------------------------------------------------------

def test_grid_and_list_expand_to_the_product_plus_the_list(tmp_path):
    spec = load_study(write(tmp_path, """
        [[scenes]]
        scene = "cornell-box"
        [foveated.defaults]
        atrous_iterations = 0
        frames = [4, 1]
        [foveated.grid]
        theta = [0.1, 0.2, 0.3]
        reconstruction = ["voronoi", "sibson"]
        spp = [1, 2]
        [[foveated.configs]]
        theta = 0.5
        frames = 2
        [[foveated.configs]]
        theta = 0.1                       # a duplicate of a grid point: runs once
        reconstruction = "voronoi"
        frames = [1, 4]
        [uniform]
        spp = [1, 4]
        denoise = [false, true]
    """))
    fov = spec.foveated
    assert len(fov) == 3 * 2 * 2 + 1
    assert {(c["options"]["theta"], c["options"]["reconstruction"], c["spp"]) for c in fov[:12]} \
        == {(t, r, s) for t in (0.1, 0.2, 0.3) for r in ("voronoi", "sibson") for s in (1, 2)}
    assert all(c["frames"] == [1, 4] and c["options"]["atrous_iterations"] == 0 for c in fov[:12])
    assert fov[12]["options"]["theta"] == 0.5 and fov[12]["frames"] == [2]
    assert fov[12]["options"]["atrous_iterations"] == 0          # defaults apply to the list
    assert spec.uniform == tuple({"spp": s, "denoise": d, "history": False}
                                 for s in (1, 4) for d in (False, True))
    tasks = expand_tasks(spec, "llvm_ad_rgb")
    assert len(tasks) == 13 + 4 and len({t["task_id"] for t in tasks}) == 17
    assert len(expand_tasks(spec, "llvm_ad_rgb", denoise_available=False)) == 13 + 2
    # the id ignores frames, repeats and warm-up, and depends on the size
    again = expand_tasks(load_study(QUICK), "llvm_ad_rgb")
    sized = expand_tasks(load_study(QUICK).with_size((32, 32)), "llvm_ad_rgb")
    assert [t["task_id"] for t in again] == [t["task_id"] for t in
                                            expand_tasks(load_study(QUICK), "llvm_ad_rgb")]
    assert not {t["task_id"] for t in again} & {t["task_id"] for t in sized}


def test_options_come_from_the_integrator_not_a_fixed_list(tmp_path, monkeypatch):
    from foveated_mi import options
    monkeypatch.setitem(options.SCHEMA, "new_option",
                        options.Option("new_option", 3, "int", "a test option", lo=0))
    spec = load_study(write(tmp_path, BASE + "new_option = [1, 2]\n"))
    assert [c["options"]["new_option"] for c in spec.foveated] == [1, 2, 1, 2]
    with pytest.raises(ParameterError, match=r"foveated\.grid\.new_option\[1\] = -1"):
        load_study(write(tmp_path, BASE + "new_option = [1, -1]\n"))


def test_relative_xml_and_optional_scene(tmp_path):
    (tmp_path / "scenes").mkdir()
    spec = load_study(write(tmp_path, """
        [[scenes]]
        scene = "scenes/nothing/scene.xml"
        optional = true
        [[scenes]]
        scene = "voxel-city"
        label = "city"
        params = { size = 16 }
        [uniform]
        spp = 1
    """))
    assert spec.scenes[0].missing and spec.scenes[0].label == "nothing"
    assert spec.scenes[0].source == str(tmp_path / "scenes" / "nothing" / "scene.xml")
    assert not spec.scenes[1].missing and spec.scenes[1].label == "city"
    assert [t["label"] for t in expand_tasks(spec, "llvm_ad_rgb")] == ["city"]


BAD = [
    ("colour = 1\n" + BASE, "colour"),
    (BASE + "thetta = [0.1]\n", "foveated.grid.thetta"),
    (BASE + "reconstruction = ['voronoi', 'bogus']\n", "foveated.grid.reconstruction[1]"),
    (BASE.replace("[0.1, 0.2]", "[0.1, -0.2]"), "foveated.grid.theta[1]"),
    (BASE + "frames = [0, 4]\n", "foveated.grid.frames[0]"),
    (BASE + "gaze = [0.5, 0.5]\n", "foveated.grid.gaze"),
    (BASE + "timing = false\n", "foveated.grid.timing"),
    (BASE + "spp = 0\n", "foveated.grid.spp"),
    (BASE + "[[foveated.configs]]\nsigma_p = 2.0\n", "foveated.configs[0].sigma_p"),
    (BASE + "[foveated.defaults]\nmax_radius = 0\n", "foveated.defaults.max_radius"),
    (BASE + "[uniform]\nspp = [1, 0]\n", "uniform.spp[1]"),
    (BASE + "[uniform]\nmethod = 'path'\n", "uniform.method"),
    (BASE + "[uniform]\nhistory = [false, 'yes']\n", "uniform.history[1]"),
    (BASE + "[uniform]\nhistory = true\npresets = ['fast']\n", "uniform.presets[0]"),
    (BASE + "[uniform]\nhistory = true\nframes = [1, 0]\n", "uniform.frames[1]"),
    (BASE + "[uniform]\nframes = [1, 16]\n", "uniform.frames"),      # no history rows
    ("seeds = [0, 1]\n" + BASE, "seed"),                               # both seed and seeds
    ("seeds = []\n" + BASE.replace("seed = 0\n", ""), "seeds"),
    ("seeds = [0, -1]\n" + BASE.replace("seed = 0\n", ""), "seeds[1]"),
    ("seeds = [2, 2]\n" + BASE.replace("seed = 0\n", ""), "seeds[1]"),
    (BASE + "[metrics]\njod = 'yes'\n", "metrics.jod"),
    (BASE + "[baseline]\nspp = 1\n", "baseline"),
    (BASE + "[metrics]\ntheta = 0\n", "metrics.theta"),
    (BASE + "[metrics]\nlpips = true\n", "metrics.lpips"),
    ("metric = 'psnr_foveal'\n" + BASE, "metric"),
    (BASE.replace('"cornell-box"', '"missing/scene.xml"'), "scenes[0].scene"),
    (BASE.replace('"cornell-box"', '"cornell"'), "scenes[0].scene"),
    (BASE.replace('scene = "cornell-box"', 'scene = "cornell-box"\nparams = {bogus = 1}'),
     "scenes[0].params.bogus"),
    (BASE.replace('scene = "cornell-box"', 'scene = "cornell-box"\ncolor = 1'),
     "scenes[0].color"),
    (BASE.replace("size = [16, 16]", "size = [16, 0]"), "size[1]"),
    (BASE.replace("size = [16, 16]", "gaze = [0.5]"), "gaze"),
    (BASE.replace("size = [16, 16]", "[reference]\nfile = 'nope.exr'"), "reference.file"),
    (BASE.replace("size = [16, 16]", "[reference]\nspp = 0"), "reference.spp"),
    (BASE.replace("size = [16, 16]", "[integrator]\ntype = 'foveated'"), "integrator.type"),
    ("seed = 0\n", "scenes"),
    (BASE + "[[foveated.configs]\n", "study"),                           # TOML syntax
]


@pytest.mark.parametrize("text,key", BAD)
def test_bad_study_files_exit_2_with_one_line(tmp_path, capsys, text, key):
    path = write(tmp_path, text)
    assert cli.main(["study", path, "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("foveated-mi: error: "), err
    if key == "study":
        assert "valid TOML" in err
    else:
        assert f"s.toml: {key} = " in err, err
    assert "expected" in err
    assert not os.path.exists(tmp_path / "out" / "results.csv")


@pytest.mark.parametrize("argv,name", [
    (["--executor", "spark"], "--executor"),
    (["--workers", "2"], "--workers"),
    (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
    (["--size", "0", "32"], "--size W"),
    (["--metric", "lpips"], "--metric"),
    (["--executor", "dask", "--scheduler", "localhost"], "--scheduler"),
    (["--executor", "dask", "--workers", "0"], "--workers"),
    (["--variant", "scalar_spectral_nope"], "variant"),
])
def test_bad_command_lines_exit_2(tmp_path, capsys, argv, name):
    rc = cli.main(["study", QUICK, "--out", str(tmp_path), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and f"error: {name} = " in err, err


def test_unreachable_scheduler_fails_fast(tmp_path, capsys, monkeypatch):
    """No scheduler at the address: exit 2 with one line once CONNECT_TIMEOUT_S ran out.
    No clock is read: a spy on Dask's client sees that timeout asked of the connection."""
    distributed = pytest.importorskip("distributed")
    from foveated_mi.study import executors
    monkeypatch.setattr(executors, "CONNECT_TIMEOUT_S", 1)
    timeouts, real_client = [], distributed.Client

    def client(*args, **kw):
        timeouts.append(kw.get("timeout"))
        return real_client(*args, **kw)

    monkeypatch.setattr(distributed, "Client", client)
    rc = cli.main(["study", QUICK, "--out", str(tmp_path), "--executor", "dask",
                   "--scheduler", "tcp://127.0.0.1:9", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "--scheduler = 'tcp://127.0.0.1:9'" in err
    assert "reachable Dask scheduler" in err and timeouts == ["1s"]


def test_missing_dask_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)       # import fails
    rc = cli.main(["study", QUICK, "--out", str(tmp_path), "--executor", "dask",
                   "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1
    assert "--executor = 'dask'" in err and "pip install -e '.[cluster]'" in err


# ---------------------------------------------------------------------------------------------
# results.csv
# ---------------------------------------------------------------------------------------------

def row(tid, frame, **kw):
    return {"task_id": tid, "frame": frame, "scene": "s", "method": "foveated", **kw}


def test_results_stream_and_repair_a_partial_last_line(tmp_path):
    path = tmp_path / "results.csv"
    with R.ResultsFile(path) as f:
        f.append(row("a", 1, psnr=math.inf, ssim=0.1 + 0.2, time_ms=None))
        f.append(row("a", 4, psnr=math.nan))
    text = path.read_text()
    assert text.count("\n") == 3 and text.splitlines()[0] == ",".join(R.columns())
    with open(path, "a") as fh:
        fh.write("b,s,foveated,0.1,0.8,sib")            # died while writing a row
    f = R.ResultsFile(path)
    assert f.repaired_bytes == len("b,s,foveated,0.1,0.8,sib")
    assert f.done == {("a", 1), ("a", 4)}
    f.append(row("b", 1))
    f.close()
    rows = R.read_rows(path)
    assert [(r["task_id"], r["frame"]) for r in rows] == [("a", 1.0), ("a", 4.0), ("b", 1.0)]
    assert rows[0]["psnr"] == math.inf and rows[0]["ssim"] == 0.1 + 0.2       # exact
    assert math.isnan(rows[0]["time_ms"]) and math.isnan(rows[1]["psnr"])
    with pytest.raises(KeyError, match="bogus"):
        with R.ResultsFile(path) as f:
            f.append(row("c", 1, bogus=1))


def test_results_header_grows_when_the_pipeline_gains_a_stage(tmp_path):
    path = tmp_path / "results.csv"
    old = [c for c in R.columns() if c != "post_ms"]
    with R.ResultsFile(path, old) as f:
        f.append(row("a", 1, trace_ms=2.5))
    with R.ResultsFile(path) as f:                         # current columns: post_ms is back
        assert f.columns[-1] == "post_ms" and f.done == {("a", 1)}
        f.append(row("b", 1, post_ms=1.5))
    rows = R.read_rows(path)
    assert rows[0]["trace_ms"] == 2.5 and math.isnan(rows[0]["post_ms"])
    assert rows[1]["post_ms"] == 1.5


def test_stage_columns_follow_timing_stages():
    from foveated_mi.timing import STAGES
    assert R.stage_columns() == [f"{s}_ms" for s in STAGES if s != "total"]


# ---------------------------------------------------------------------------------------------
# Pareto fronts
# ---------------------------------------------------------------------------------------------

def test_pareto_front_on_hand_made_points():
    t = [10, 5, 20, 5, 7, 30, 8, 12, math.nan, 1]
    q = [30, 20, 35, 22, 22, 34, math.inf, 30, 99, math.nan]
    # by hand: (5, 22) beats (5, 20); (7, 22) is dominated by (5, 22); (10, 30) is on the
    # front; (12, 30) is dominated by (10, 30); (20, 35) tops it; (30, 34) is dominated.
    # Non-finite points never count.
    assert pareto_front(t, q) == [3, 0, 2]
    assert pareto_front([1, 1, 1], [5, 5, 5]) == [0]                      # duplicates: first
    assert pareto_front([], []) == []
    assert pareto_front([3, 2, 1], [1, 2, 3]) == [2]                      # one dominates all
    assert pareto_front([1, 2, 3], [1, 2, 3]) == [0, 1, 2]                # a trade-off line


def test_scene_fronts_flip_is_lower_is_better():
    rows = [dict(scene="a", time_ms=1.0, flip=0.3), dict(scene="a", time_ms=2.0, flip=0.1),
            dict(scene="a", time_ms=3.0, flip=0.2), dict(scene="b", time_ms=1.0, flip=0.5)]
    fr = scene_fronts(rows, "flip")
    assert [r["time_ms"] for r in fr["a"]] == [1.0, 2.0] and len(fr["b"]) == 1


def test_front_table_names_the_options_that_vary():
    import json
    from foveated_mi.study import front_table

    def r(t, q, reorder):
        cfg = {"full_options": {"theta": 0.1, "reorder": reorder, "max_radius": 32}}
        return dict(scene="s", method="foveated", theta=0.1, sigma_p=0.8,
                    reconstruction="sibson", spp=1.0, frame=1.0, time_ms=t, psnr=q,
                    config=json.dumps(cfg))
    text = front_table([r(2.0, 20.0, "none"), r(1.0, 19.0, "compact"),
                        r(3.0, 18.0, "rows")], "psnr")
    lines = text.splitlines()
    assert lines[0].split()[-1] == "options" and len(lines) == 4     # header, rule, 2 rows
    assert lines[2].endswith("reorder=compact") and lines[3].endswith("reorder=none")
    assert "max_radius" not in text                                   # the same everywhere
    # The preset names the pipeline ("foveated, stochastic" alone would hide it).
    named = front_table([dict(r(1.0, 19.0, "compact"), config=json.dumps(
        {"full_options": {"preset": "oidn", "reorder": "compact"}}))], "psnr")
    assert "foveated oidn" in named.splitlines()[2]
    # A row formed in the foveal buffer reads neither sigma_p nor a reconstruction.
    vr = front_table([dict(r(1.0, 19.0, "tiles"), config=json.dumps(
        {"full_options": {"preset": "vr", "formation": "foveal", "theta": 0.15}}))], "psnr")
    cells = vr.splitlines()[2].split()
    assert cells[1:5] == ["foveated", "vr", "0.1", "-"] and cells[5] == "-", vr
    film = front_table([r(1.0, 19.0, "tiles")], "psnr").splitlines()[2].split()
    assert film[3:5] == ["0.8", "sibson"]


def test_uniform_history_rows_and_seeds_expand(tmp_path):
    spec = load_study(write(tmp_path, """
        seeds = [0, 1, 2]
        [[scenes]]
        scene = "cornell-box"
        [foveated.defaults]
        frames = [1, 16]
        [[foveated.configs]]
        preset = "guided"
        [[foveated.configs]]
        preset = "paper"
        [uniform]
        spp = [1, 2]
        denoise = [false, true]
        history = [false, true]
    """))
    assert spec.seeds == (0, 1, 2) and spec.seed == 0
    hist = [u for u in spec.uniform if u["history"]]
    # presets and frames default to the foveated configurations'; every pixel traced
    assert {u["preset"] for u in hist} == {"guided", "paper"}
    assert all(u["frames"] == [1, 16] and u["options"]["sigma_p"] == 1.0 and
               u["options"]["history"] for u in hist)
    den = {(u["preset"], u["denoise"]): u["denoiser"] for u in hist if u["spp"] == 1}
    assert den == {("guided", True): "svgf", ("paper", True): "atrous",
                   ("guided", False): "none", ("paper", False): "none"}
    assert all(u["options"]["denoiser"] == u["denoiser"] for u in hist)
    # Every pixel traced: guided's reconstruction, which averages them, is not run there.
    assert {u["options"]["reconstruction"] for u in hist} == {"sibson"}
    tasks = expand_tasks(spec, "llvm_ad_rgb")
    per_seed = 2 + 2 * 2 + len(hist)          # foveated, uniform (+ OIDN), with history
    assert len(tasks) == 3 * per_seed and len({t["task_id"] for t in tasks}) == len(tasks)
    assert {t["seed"] for t in tasks} == {0, 1, 2}
    methods = {t["method"] for t in tasks}
    assert {"uniform+history", "uniform+history+svgf", "uniform+history+atrous"} <= methods
    h = [t for t in tasks if t["method"] == "uniform+history+svgf"]
    assert all(t["kind"] == "foveated" and t["frames"] == [1, 16] for t in h)
    # explicit presets and frames; without OIDN its history rows are left out, like uniform+oidn
    spec = load_study(write(tmp_path, """
        [[scenes]]
        scene = "cornell-box"
        [uniform]
        denoise = true
        history = [true]
        presets = ["oidn", "guided"]
        frames = 4
    """))
    assert [(u["preset"], u["frames"]) for u in spec.uniform] == [("oidn", [4]), ("guided", [4])]
    assert [t["method"] for t in expand_tasks(spec, "llvm_ad_rgb", denoise_available=False)] \
        == ["uniform+history+svgf"]


def test_a_vr_study_s_uniform_history_rows_trace_every_pixel(tmp_path):
    """vr's cells take ray_budget of the pixels whatever sigma_p says: its uniform rows with
    history run guided (the same history and SVGF) at sigma_p = 1, which traces them all."""
    import mitsuba as mi
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    spec = load_study(write(tmp_path, """
        [[scenes]]
        scene = "cornell-box"
        [[foveated.configs]]
        preset = "vr"
        [[foveated.configs]]
        preset = "auto"
        [uniform]
        denoise = [false, true]
        history = [true]
    """))
    assert [(u["preset"], u["denoiser"]) for u in spec.uniform] == [("guided", "none"),
                                                                   ("guided", "svgf")]
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=32, height=32)
    sc = mi.load_dict(d)
    fractions = {}
    for name, opts in (("row", spec.uniform[1]["options"]),
                       ("vr", {"preset": "vr", "sigma_p": 1.0})):
        integ = FoveatedIntegrator(**{k: v for k, v in opts.items() if k != "gaze"})
        mi.render(sc, integrator=integ, spp=1)
        fractions[name] = integ.stats["ray_fraction"]
    assert fractions["row"] == 1.0 and fractions["vr"] < 0.9, fractions


def test_a_uniform_history_row_holds_the_history_and_no_filter(tmp_path):
    """The ``uniform + history`` row of a preset whose reconstruction averages traced pixels
    (``guided``): its frames are the traced pixels blended with their history, as the same
    integrator shows them with the paper's interpolation, and not the guided average."""
    import mitsuba as mi
    import numpy as np
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    spec = load_study(write(tmp_path, """
        [[scenes]]
        scene = "cornell-box"
        [[foveated.configs]]
        preset = "guided"
        [uniform]
        denoise = false
        history = [true]
    """))
    row, = spec.uniform
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=32, height=24)
    sc = mi.load_dict(d)

    def frames(**opts):
        integ = FoveatedIntegrator(nested=sc.integrator(), **opts)
        return [np.array(mi.render(sc, integrator=integ, spp=1, seed=k)) for k in range(3)]

    shown = frames(**row["options"])
    plain = frames(preset="guided", sigma_p=1.0, history=True, denoiser="none",
                   reconstruction="sibson")
    averaged = frames(preset="guided", sigma_p=1.0, history=True, denoiser="none")
    for a, b, c in zip(shown, plain, averaged):
        np.testing.assert_array_equal(a, b)
        assert np.abs(a - c).mean() > 1e-3          # the guided average would differ


def test_one_seed_keeps_the_task_ids_of_studies_without_seeds():
    spec = load_study(QUICK)
    import dataclasses
    from foveated_mi.study import tasks as T
    ids = [t["task_id"] for t in expand_tasks(spec, "llvm_ad_rgb")]
    # the ids as they were computed before seeds and perceptual settings existed
    old = []
    for scene in spec.scenes:
        ident = scene.identity()
        old += [T.task_id(ident, "foveated", c["options"], c["spp"], spec.seed, "llvm_ad_rgb",
                          spec.metrics) for c in spec.foveated]
        old += [T.task_id(ident, "uniform+oidn" if u["denoise"] else "uniform",
                          {"denoise": u["denoise"]}, u["spp"], spec.seed, "llvm_ad_rgb",
                          spec.metrics) for u in spec.uniform]
    assert ids == old
    other = dataclasses.replace(spec, perceptual={"jod": True, "display": "standard_4k"})
    assert not set(ids) & {t["task_id"] for t in expand_tasks(other, "llvm_ad_rgb")}


@pytest.mark.parametrize("name", ["quick", "paper_fig7_quality", "speed_accuracy",
                                  "paper_table1", "equal_time"])
def test_example_studies_parse(name):
    spec = load_study(os.path.join(os.path.dirname(QUICK), f"{name}.toml"))
    tasks = expand_tasks(spec, "llvm_ad_rgb")
    assert tasks and len({t["task_id"] for t in tasks}) == len(tasks)
    if name == "paper_fig7_quality":
        combos = {(c["options"]["theta"], c["options"]["reconstruction"]) for c in spec.foveated}
        assert {t for t, _ in combos} == {0.04, 0.1, 0.2} and len(combos) == 12
        assert all(c["options"]["sigma_p"] == 0.8 for c in spec.foveated)
        assert spec.scenes[0].size == (1024, 1024) and spec.scenes[0].name == "voxel-city"
    if name == "speed_accuracy":
        assert [s.label for s in spec.scenes] == ["voxel-city", "staircase"]
        assert spec.scenes[1].optional
        assert spec.scenes[1].source.endswith(os.path.join("shared", "scenes", "staircase",
                                                           "scene.xml"))


def test_pareto_legend_names_every_family_of_every_panel():
    """Each baseline family has a marker and a legend entry of its own, also one that appears
    only on a later panel; a plot without labels draws no legend (and no warning)."""
    import json
    import warnings
    from foveated_mi.study.pareto import pareto_figure

    def row(scene, method, t, q, preset=None):
        config = json.dumps({"full_options": {"preset": preset}}) if preset else ""
        return {"scene": scene, "method": method, "time_ms": t, "psnr": q, "frame": 1,
                "reconstruction": "stochastic" if preset else "", "config": config,
                "theta": 0.1, "sigma_p": 0.8, "spp": 1}

    rows = [row("a", "foveated", 10.0, 30.0, "oidn"), row("a", "uniform", 12.0, 25.0),
            row("a", "uniform+oidn", 15.0, 29.0),
            row("b", "uniform+history", 12.0, 27.0), row("b", "uniform+history+oidn", 16.0, 33.0),
            row("b", "uniform+history+svgf", 14.0, 31.0)]
    fig = pareto_figure(rows, "psnr")
    legend = fig.axes[0].get_legend()
    labels = [t.get_text() for t in legend.get_texts()]
    for label in ("foveated oidn, stochastic", "uniform", "uniform + OIDN", "uniform + history",
                  "uniform + history + OIDN", "uniform + history + SVGF", "Pareto front"):
        assert labels.count(label) == 1, (label, labels)
    # Five baseline families, five marker shapes.
    shapes = {h.get_paths()[0].vertices.round(3).tobytes()
              for h, label in zip(legend.legend_handles, labels) if label.startswith("uniform")}
    assert len(shapes) == 5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        empty = pareto_figure([row("a", "foveated", float("nan"), float("nan"), "oidn")], "psnr")
    assert empty.axes[0].get_legend() is None


def test_a_misspelt_option_in_a_study_names_the_closest_one(tmp_path, capsys):
    path = write(tmp_path, BASE.replace("theta = [0.1, 0.2]", "thetta = [0.1, 0.2]"))
    assert cli.main(["study", path, "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "foveated.grid.thetta" in err, err
    assert "did you mean 'theta'?" in err and len(err.split("s.toml: ", 1)[1]) < 120, err
    path = write(tmp_path, BASE.replace("theta = [0.1, 0.2]", "zzzz = 1"))
    assert cli.main(["study", path, "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "none is close" in err and "sigma_p" not in err, err


# ---------------------------------------------------------------------------------------------
# an eye tracker: latency and noise of the rendered gaze
# ---------------------------------------------------------------------------------------------

TRACKED = BASE + """
[viewer]
fov = "sensor"
{viewer}
[motion]
frames = 12
fps = 90
[motion.gaze]
type = "saccades"
targets = [[0.3, 0.4], [0.7, 0.6]]
dwell = 0.03
duration = 0.02
"""


def _motion(tmp_path, viewer=""):
    study = load_study(write(tmp_path, TRACKED.format(viewer=viewer)))
    return study, study.scenes[0].motion


def test_no_tracker_and_a_zero_tracker_are_the_same_study(tmp_path):
    plain, m0 = _motion(tmp_path)
    zero, m1 = _motion(tmp_path, "gaze_latency_ms = 0.0\ngaze_noise_deg = 0.0")
    assert m0 == m1 and "rendered_gazes" not in m1 and "gaze_noise_deg" not in m1
    ids = [[t["task_id"] for t in expand_tasks(s, "llvm_ad_rgb")] for s in (plain, zero)]
    assert ids[0] == ids[1] and len(ids[0]) > 1


def test_a_latency_of_one_frame_renders_the_previous_frame_s_gaze(tmp_path):
    _, m = _motion(tmp_path, f"gaze_latency_ms = {1000.0 / 90.0!r}")
    gazes, late = m["gazes"], m["rendered_gazes"]
    assert late == [gazes[0]] + gazes[:-1]
    assert any(a != b for a, b in zip(gazes, late))        # the saccades do move the gaze


def test_a_latency_between_frames_reads_the_path_that_much_earlier(tmp_path):
    from foveated_mi.config import gaze_path
    from foveated_mi.study.spec import TableContext
    _, m = _motion(tmp_path, "gaze_latency_ms = 50.0")
    path = gaze_path(TableContext("t"), {"type": "saccades", "targets": [[0.3, 0.4], [0.7, 0.6]],
                                         "dwell": 0.03, "duration": 0.02}, ".")
    for k, g in enumerate(m["rendered_gazes"]):
        assert g == [float(v) for v in path.at(max(k / 90 - 0.05, 0.0))]


@pytest.mark.parametrize("viewer,key", [("gaze_latency_ms = -1.0", "viewer.gaze_latency_ms"),
                                        ("gaze_noise_deg = -0.5", "viewer.gaze_noise_deg"),
                                        ("gaze_noise_deg = 'a'", "viewer.gaze_noise_deg")])
def test_a_bad_tracker_gets_one_line(tmp_path, viewer, key):
    with pytest.raises(ParameterError, match=rf"{key} = .* is invalid") as e:
        _motion(tmp_path, viewer)
    assert "\n" not in str(e.value)


def test_tracker_noise_has_the_deviation_it_asks_for_in_degrees(tmp_path):
    """2000 gazes jittered by 0.5 degrees: the sample deviation of the jitter, converted back
    at the film's pixels per degree, is 0.5 within 10 % (its own standard error is 1.6 %)."""
    import numpy as np
    from foveated_mi.scenes import load_scene
    from foveated_mi.study.tasks import rendered_gazes
    from foveated_mi.viewer import pixels_per_degree
    scene = load_scene("cornell-box", width=400, height=300)
    n, g = 2000, [0.5, 0.5]
    task = {"seed": 3, "scene": {"width": 400, "height": 300},
            "motion": {"gazes": [g] * n, "gaze_noise_deg": 0.5}}
    out = np.array(rendered_gazes(scene, task))
    ppd = pixels_per_degree(scene.sensors()[0], tuple(g))
    deg = (out - g) * [400, 300] / ppd
    assert abs(deg.std(axis=0) - 0.5).max() < 0.05, deg.std(axis=0)
    assert np.array_equal(out, np.array(rendered_gazes(scene, task)))      # seeded
    assert rendered_gazes(scene, dict(task, motion={"gazes": [g] * 3})) == [g] * 3


def test_saccades_that_never_start_within_the_sequence_get_a_note(tmp_path):
    # dwell 0.03 s + 0.02 s of saccade at 90 Hz: the first saccade starts at frame 2.7.
    short = TRACKED.format(viewer="").replace("dwell = 0.03", "dwell = 0.3")
    held = load_study(write(tmp_path, short))
    assert len(held.notes) == 1 and "hold one fixation" in held.notes[0]
    assert "\n" not in held.notes[0] and "ms at 90 Hz" in held.notes[0]
    moving, _ = _motion(tmp_path)
    assert moving.notes == ()
