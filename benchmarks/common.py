"""Helpers shared by the benchmarks (not part of the package API); ``python -m benchmarks``
runs them (:mod:`benchmarks.__main__`)."""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time

import drjit as dr
import mitsuba as mi


def timed(fn, *args, **kw):
    dr.sync_thread()
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    dr.eval(out)
    dr.sync_thread()
    return out, (time.perf_counter() - t0) * 1e3


def median(xs):
    return statistics.median(xs) if xs else float("nan")


def machine() -> dict:
    info = {"variant": mi.variant(), "python": platform.python_version(),
            "mitsuba": mi.__version__, "drjit": dr.__version__,
            "cpu_count": os.cpu_count(), "machine": platform.machine()}
    if mi.variant().startswith("cuda"):
        try:
            import subprocess
            info["gpu"] = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                                         capture_output=True, text=True).stdout.strip()
        except OSError:
            pass
    return info


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; else what :mod:`platform` says)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def commit() -> str | None:
    """The checkout's commit (``git rev-parse HEAD``), or None outside a git checkout."""
    import subprocess
    try:
        r = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                           cwd=os.path.dirname(os.path.abspath(__file__)), timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() or None if r.returncode == 0 else None


def run_info() -> dict:
    """What every result carries: the machine, its CPU, the commit, the date and the variant."""
    return {"platform": platform.platform(), "cpu_model": cpu_model(),
            "cpu_count": os.cpu_count(), "commit": commit(),
            "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "variant": mi.variant(),
            "mitsuba": mi.__version__, "drjit": dr.__version__}


def parser(doc: str, *, out: str | None = None,
           out_help: str = "write the results to this JSON file") -> argparse.ArgumentParser:
    """The command line every benchmark starts from: ``--variant`` and ``--out``.

    Parameters
    ----------
    doc : str
        The benchmark's docstring; its first line describes the command.
    out : str or None, optional
        The default of ``--out`` (None: write nothing unless asked).
    out_help : str, optional
        What ``--out`` names.

    Returns
    -------
    parser : argparse.ArgumentParser
        A parser to add the benchmark's own flags to.
    """
    p = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    p.add_argument("--variant", help="Mitsuba variant (default: $FOVEATED_MI_VARIANT, else "
                   "cuda_ad_rgb where CUDA works, else llvm_ad_rgb)")
    p.add_argument("--out", default=out,
                   help=out_help + (" (default %(default)s)" if out is not None else ""))
    return p


def setup(args: argparse.Namespace) -> str:
    """Set the variant that ``args.variant`` names (None: the package's choice) and register
    the ``foveated`` integrator for it; an unavailable variant exits with one line.

    Returns
    -------
    variant : str
        The variant set.
    """
    import foveated_mi
    from foveated_mi.validate import ParameterError
    try:
        return foveated_mi.set_variant(args.variant)
    except ParameterError as e:
        sys.stderr.write(f"error: {e}\n")
        raise SystemExit(2) from None


def write_json(path: str | None, payload: dict | list, *, default=None) -> None:
    """``payload`` as JSON at ``path`` (nothing without one), with :func:`run_info` under
    ``run``: the one output format of the benchmarks. A list of rows is written as
    ``{"rows": [...]}``; ``default`` is :func:`json.dump`'s, for values JSON lacks."""
    if not path:
        return
    rows = {"rows": payload} if isinstance(payload, list) else payload
    payload = {**rows, "run": run_info()}
    from foveated_mi.io import atomic_write
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with atomic_write(path, "w") as f:
        json.dump(payload, f, indent=2, default=default)


def md_table(header, rows) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def preset_edges(scene, preset="paper", **options):
    """The edge rays the ``foveated`` integrator would force on ``scene``'s first sensor
    under ``preset`` (its edge detector and threshold; ``options`` override), or None when
    the threshold is 0."""
    from foveated_mi.frame.gbuffer import render_gbuffer
    from foveated_mi.kernels import film_size
    from foveated_mi.options import validate_options
    from foveated_mi.frame.sampling import depth_edges
    o = validate_options({"preset": preset, **options})
    if o["edge_threshold"] <= 0:
        return None
    sensor = scene.sensors()[0]
    W, H = film_size(sensor)
    gb = render_gbuffer(scene, sensor)
    return depth_edges(gb.depth, gb.hit, W, H, o["edge_threshold"], detector=o["edge_detector"])


def calibrate_theta(width, height, target, *, sigma_p, gaze=(0.5, 0.5), edges=None, seed=0):
    """θ whose sampling map (edge rays ``edges`` included, e.g. from :func:`preset_edges`)
    traces about ``target`` of the pixels. Raises ValueError when the edge rays alone
    exceed the target."""
    from foveated_mi.frame.sampling import sampling_map
    if edges is not None:
        forced = dr.count(edges)[0] / (width * height)
        if forced > target:
            raise ValueError(f"target = {target!r} is invalid: expected at least the edge-ray "
                             f"fraction {forced:.4f}")
    lo, hi = 1e-4, 10.0
    for _ in range(30):
        mid = (lo * hi) ** 0.5
        smap, _ = sampling_map(width, height, gaze=gaze, theta=mid, sigma_p=sigma_p, seed=seed,
                               edges=edges)
        frac = dr.count(smap)[0] / (width * height)
        lo, hi = (mid, hi) if frac < target else (lo, mid)
    return (lo * hi) ** 0.5


def scene_with_reference(name, width, height, *, max_depth, ref_spp, seed=12345):
    """Built-in or XML scene with a path tracer, and its converged reference (linear, NumPy).

    The reference is rendered with an explicit spp; callers must pass ``spp`` explicitly too,
    since ``mi.render(spp=N)`` leaves N as the sensor's sample count."""
    import numpy as np
    from foveated_mi.scenes import load_scene
    scene = load_scene(name, width=width, height=height, spp=1,
                       integrator={"type": "path", "max_depth": max_depth})
    ref = np.array(mi.render(scene, integrator=scene.integrator(), spp=ref_spp, seed=seed))
    return scene, ref


def parse_sets(items: list[str]) -> dict:
    """``["reorder='tiles'", "ray_budget=0.2"]`` -> the options they set."""
    import ast
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--set {item!r}: expected OPTION=VALUE")
        try:
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[key] = value          # a bare word: a string option's value
    return out
