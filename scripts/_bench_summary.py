"""One-page summary of a ``scripts/gpu_bench.sh`` run (standard library only).

    python scripts/_bench_summary.py OUTDIR [--variant cuda_ad_rgb]

Reads OUTDIR/steps.csv, gpu.txt and the benchmarks' JSON/CSV files, and writes
OUTDIR/summary.md, summary.json and reorder.csv (every bench_reorder run, one row per mode).
"""
from __future__ import annotations

import argparse
import csv
import glob
import json
import os
import sys


def _read(path: str, default: str = "") -> str:
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.read().strip()
    except OSError:
        return default


def _json(path: str):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def read_steps(out: str) -> list[dict]:
    rows = []
    for line in _read(os.path.join(out, "steps.csv")).splitlines()[1:]:
        parts = line.split(",", 4)
        if len(parts) == 5:
            rows.append(dict(zip(("step", "status", "seconds", "limit_s", "note"), parts)))
    return rows


def reorder_rows(out: str) -> list[dict]:
    rows = []
    for path in sorted(glob.glob(os.path.join(out, "reorder_*.json"))
                       + glob.glob(os.path.join(out, "table1_*.json"))):
        d = _json(path)
        if not isinstance(d, dict) or "modes" not in d:
            continue
        args = d.get("args", {})
        full = d.get("full_ms")
        size = args.get("size", ["?", "?"])
        for mode, m in d["modes"].items():
            total = m.get("total_ms")
            rows.append({"run": os.path.basename(path)[:-5], "scene": args.get("scene", "?"),
                         "size": f"{size[0]}x{size[1]}", "mode": mode,
                         "ray_fraction": m.get("ray_fraction"), "trace_ms": m.get("trace_ms"),
                         "reorder_ms": m.get("reorder_ms"), "total_ms": total, "full_ms": full,
                         "speedup": (full / total) if full and total else None,
                         "compiled_after_first": d.get("compiled_after_first")})
    return rows


def _f(v, fmt=".1f") -> str:
    return "-" if v is None else format(v, fmt)


def _num(text, fmt=".1f") -> str:
    """A CSV cell as a rounded number, or as it is when it is not one."""
    try:
        return format(float(text), fmt)
    except (TypeError, ValueError):
        return "-" if text in (None, "") else str(text)


def summarise(out: str, variant: str) -> str:
    steps = read_steps(out)
    gpu = _read(os.path.join(out, "gpu.txt"), "unknown")
    reorder = reorder_rows(out)
    if reorder:
        with open(os.path.join(out, "reorder.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(reorder[0]))
            w.writeheader()
            w.writerows(reorder)
    backward = []
    for path in sorted(glob.glob(os.path.join(out, "backward_*.json"))):
        d = _json(path)
        backward += d if isinstance(d, list) else (d or {}).get("rows", [])  # older: a list
    tests_log = _read(os.path.join(out, "logs", "tests.log")).splitlines()
    tests_last = next((l for l in reversed(tests_log) if l.strip() and not l.startswith("not collected")), "")
    not_collected = next((l for l in tests_log if l.startswith("not collected")), "")
    failed = [s for s in steps if s["status"] not in ("ok", "skipped")]

    md = [f"# gpu_bench on {gpu.splitlines()[0] if gpu else 'unknown'}", "",
          f"GPU, driver, memory: {gpu.replace(chr(10), '; ')}  ",
          f"Variant: {variant}; Python {_read(os.path.join(out, 'python.txt'), '?')}; "
          f"total step time {sum(float(s['seconds']) for s in steps):.0f} s.  ",
          f"Failed or timed out: {', '.join(s['step'] for s in failed) or 'none'}.", "",
          "| step | status | s | limit s | note |", "|---|---|---|---|---|"]
    md += [f"| {s['step']} | {s['status']} | {s['seconds']} | {s['limit_s']} | {s['note']} |"
           for s in steps]
    if reorder:
        md += ["", "## Ray reordering (bench_reorder; medians, ms per frame)", "",
               "| run | scene | size | mode | rays | trace | reorder | total | full | speed-up |",
               "|---|---|---|---|---|---|---|---|---|---|"]
        md += [f"| {r['run']} | {r['scene']} | {r['size']} | {r['mode']} | "
               f"{_f(r['ray_fraction'], '.3f')} | {_f(r['trace_ms'])} | {_f(r['reorder_ms'])} | "
               f"{_f(r['total_ms'])} | {_f(r['full_ms'])} | {_f(r['speedup'], '.2f')} |"
               for r in reorder]
    if backward:
        md += ["", "## Gradient step (bench_backward)", "",
               "| size | configuration | primal ms | step ms | backward ms | peak MiB |",
               "|---|---|---|---|---|---|"]
        for r in backward:
            if "error" in r:
                md.append(f"| {r.get('size')} | {r.get('config')} | failed: {r['error']} | | | |")
            else:
                md.append(f"| {r.get('size')} | {r.get('config')} | {_f(r.get('primal_ms'), '.0f')} "
                          f"| {_f(r.get('step_ms'), '.0f')} | {_f(r.get('backward_ms'), '.0f')} "
                          f"| {_f(r.get('peak_mib'), '.0f')} |")
    cell = os.path.join(out, "equal_time_cell", "results.csv")
    if os.path.exists(cell):
        with open(cell, newline="") as f:
            rows = list(csv.DictReader(f))
        md += ["", "## Equal-time cell", "", "| method | spp | frame | time ms | PSNR fovea | PSNR |",
               "|---|---|---|---|---|---|"]
        md += [f"| {r.get('method')} | {r.get('spp')} | {r.get('frame')} | {_num(r.get('time_ms'))} "
               f"| {_num(r.get('psnr_fovea'), '.2f')} | {_num(r.get('psnr'), '.2f')} |" for r in rows]
    overhead = []
    for name in ("overhead.json", "overhead_2x.json", "overhead_2x_host.json"):
        overhead += (_json(os.path.join(out, name)) or {}).get("results") or []
    if overhead:
        stages = list(overhead[0].get("stages_ms", {}))
        md += ["", "## Frame time per stage (bench_overhead; medians, ms)", "",
               "| case | size | preset | rays | full | foveated | speed-up | "
               + " | ".join(stages) + " | overhead x full | kernels | kernel ms | image |",
               "|---|---|---|---|---|---|---|" + "---|" * len(stages) + "---|---|---|---|"]
        for r in overhead:
            size = r.get("size") or ["?", "?"]
            md.append(f"| {r.get('case')} | {size[0]}x{size[1]} | {r.get('preset')} | "
                      f"{_f(100 * r['ray_fraction'] if r.get('ray_fraction') is not None else None)} % | "
                      f"{_f(r.get('full_ms'))} | {_f(r.get('frame_ms'))} | x{_f(r.get('speedup'), '.2f')} | "
                      + " | ".join(_f(r.get("stages_ms", {}).get(s)) for s in stages)
                      + f" | {_f(r.get('overhead_x_full'), '.2f')} | {_f(r.get('kernels_per_frame'), '.0f')}"
                      f" | {_f(r.get('kernel_ms'))} | {'to host' if r.get('image_to_host') else 'device'} |")
    if overhead:
        md += ["", "Kernel ms: the time the foveated frame's kernels ran (from Dr.Jit's kernel history); "
               "image: forced on the device (dr.eval + dr.sync_thread) or copied to a NumPy array."]
    for name in ("overhead.json", "overhead_2x.json", "overhead_2x_host.json", os.path.join("table1", "results.csv")):
        if os.path.exists(os.path.join(out, name)):
            md += ["", f"Also written: `{name}`."]
    stereo = [r for r in ((_json(os.path.join(out, n)) or {}).get("result")
                          for n in sorted(os.listdir(out)) if n.startswith("stereo_")) if r]
    if stereo:
        md += ["", "## Two eyes (bench_stereo_frame; medians, ms)", "",
               "| headset | eye buffer | full (one eye) | vr one eye | vr stereo | no reuse "
               "| stereo x one eye | x uniform stereo |", "|---|---|---|---|---|---|---|---|"]
        for r in stereo:
            ms = r.get("median_ms", {})
            md.append(f"| {r.get('headset')} | {'x'.join(map(str, r.get('eye_buffer', [])))} | "
                      + " | ".join(_f(ms.get(c), ".2f") for c in ("full", "vr one eye", "vr stereo",
                                                                   "vr stereo, no reuse"))
                      + f" | x{_f(r.get('stereo_x_one_eye'), '.2f')}"
                      f" | x{_f(r.get('speedup_vs_uniform_stereo'), '.2f')} |")
    parity_log = _read(os.path.join(out, "logs", "tests_parity.log")).splitlines()
    parity_last = next((l for l in reversed(parity_log) if l.strip() and not l.startswith("not collected")), "")
    if parity_last:
        md += ["", "## Backend parity and kernel budget tests", "", f"`{parity_last.strip()}`"]
    if tests_last:
        md += ["", "## Tests", "", f"`{tests_last.strip()}`"]
        if not_collected:
            md += ["", not_collected]
    text = "\n".join(md) + "\n"
    with open(os.path.join(out, "summary.md"), "w") as f:
        f.write(text)
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump({"gpu": gpu, "variant": variant, "steps": steps, "reorder": reorder,
                   "backward": backward, "overhead": overhead, "stereo": stereo, "tests": tests_last.strip(), "tests_parity": parity_last.strip(),
                   "failed": [s["step"] for s in failed]}, f, indent=2)
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--variant", default="cuda_ad_rgb")
    a = ap.parse_args(argv)
    if not os.path.exists(os.path.join(a.out, "steps.csv")):
        print(f"out: {a.out} has no steps.csv (not a gpu_bench.sh output folder)", file=sys.stderr)
        return 1
    summarise(a.out, a.variant)
    return 0


if __name__ == "__main__":
    sys.exit(main())
