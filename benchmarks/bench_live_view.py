"""The live view's frame rate and gaze latency, as a viewer gets them.

Starts ``foveated-mi view`` (a separate process, as a user would) and measures, over the
page's own socket:

- **browser** (headless Chromium driven by selenium): the page loaded, the mouse moving over
  the image (synthetic ``mousemove`` events along a circle, 60 a second, dispatched in the
  page so that the harness costs no CPU; with ``--mover driver``, selenium's pointer actions
  through chromedriver, whose CPU the renderer shares), the frames per second the page
  *received and drew* with the split view off, then with it on (uniform rendering with the
  same rays, then the converged still), and the gaze latency: from each mouse-move event to
  the first frame drawn that was rendered with that gaze (or a later one), measured in the
  page;
- **python**: a plain Python client (:mod:`foveated_mi.live.client`) speaking the page's
  protocol, for a machine without a browser: the same rates and latency, without drawing.

    python benchmarks/bench_live_view.py                      # voxel-city 480x270, vr, 1 spp
    python benchmarks/bench_live_view.py --client python --seconds 5 --out out/live.json

Targets: at least 15 frames per second with the split view off, and a gaze latency of at most
two frame times (the frame being rendered when the gaze moves, then the frame with it).
"""
from __future__ import annotations

import math
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))   # the browser helper the tests use

from common import parser, setup, write_json  # noqa: E402

TARGET_FPS = 15.0
TARGET_LATENCY_FRAMES = 2.0


def start_server(args) -> tuple[subprocess.Popen, str]:
    cmd = [sys.executable, "-m", "foveated_mi.cli", "view", args.scene, "--size",
           str(args.size[0]), str(args.size[1]), "--preset", args.preset, "--spp",
           str(args.spp), "--port", "0", "--token", "--record-dir",
           tempfile.mkdtemp(prefix="bench-live-"), "--max-fps", str(args.max_fps)]
    if args.variant:
        cmd += ["--variant", args.variant]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT)
    line = proc.stdout.readline()
    m = re.search(r"(http://\S+)", line)
    if not m:
        proc.kill()
        raise SystemExit(f"the server did not start: {line}{proc.stderr.read()}")
    return proc, m.group(1)


def stop_server(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(20)
    except subprocess.TimeoutExpired:
        proc.kill()


def summarise(arrivals_ms: list[float], latencies_ms: list[float], render_ms: list[float]):
    span = (arrivals_ms[-1] - arrivals_ms[0]) / 1e3 if len(arrivals_ms) > 1 else 0.0
    fps = (len(arrivals_ms) - 1) / span if span > 0 else 0.0
    frame_ms = 1e3 / fps if fps else math.nan
    lat = sorted(latencies_ms)
    med = statistics.median(lat) if lat else math.nan
    p95 = lat[min(len(lat) - 1, int(round(0.95 * (len(lat) - 1))))] if lat else math.nan
    return {"frames": len(arrivals_ms), "seconds": span, "fps": fps, "frame_time_ms": frame_ms,
            "render_ms_median": statistics.median(render_ms) if render_ms else math.nan,
            "latency_ms_median": med, "latency_ms_p95": p95,
            "latency_frames_median": med / frame_ms if fps else math.nan,
            "latency_samples": len(lat)}


# -- the browser ----------------------------------------------------------------------------

MOVER = """
const stage = document.getElementById("stage"), view = document.getElementById("view");
const t0 = performance.now();
window.__mover = setInterval(() => {
  const r = view.getBoundingClientRect(), panels = window.live.meta ? window.live.meta.panels : 1;
  const a = 2 * Math.PI * 0.5 * (performance.now() - t0) / 1000;
  const u = 0.5 + 0.3 * Math.cos(a), v = 0.5 + 0.3 * Math.sin(a);
  stage.dispatchEvent(new MouseEvent("mousemove", {bubbles: true,
    clientX: r.left + u / panels * r.width, clientY: r.top + v * r.height}));
}, 1000 / 60);
"""


def drive_mouse(d, seconds: float) -> None:
    """Move the mouse through chromedriver (selenium's pointer actions) for ``seconds``."""
    from selenium.webdriver.common.action_chains import ActionChains
    el = d.find_element("id", "view")
    t0 = time.time()
    while time.time() - t0 < seconds:
        w, h = el.size["width"], el.size["height"]
        panels = d.execute_script("return window.live.meta.panels")
        a = 2 * math.pi * 0.5 * (time.time() - t0)
        u, v = 0.5 + 0.3 * math.cos(a), 0.5 + 0.3 * math.sin(a)
        ActionChains(d, duration=0).move_to_element_with_offset(
            el, int((u / panels - 0.5) * w), int((v - 0.5) * h)).perform()


def browser_phase(d, seconds: float, split: str, mover: str = "page") -> dict:
    from selenium.webdriver.support.ui import Select
    Select(d.find_element("id", "split")).select_by_value(split)

    def wait_panels():
        end = time.time() + 60
        want = 1 if split == "off" else 2
        while time.time() < end:
            m = d.execute_script("return window.live.meta")
            if m and m["panels"] == want:
                return
            time.sleep(0.05)
        raise SystemExit(f"the split view '{split}' did not appear")
    wait_panels()

    move = (lambda t: time.sleep(t)) if mover == "page" else (lambda t: drive_mouse(d, t))
    if mover == "page":
        d.execute_script(MOVER)
    move(2.0)                                          # warm-up: kernels, the still's passes
    n_arr, n_lat, n_frames = d.execute_script(
        "return [window.live.arrivals.length, window.live.latencies.length, "
        "window.live.frames.length]")
    first_frame = d.execute_script("return window.live.meta.frame")
    move(seconds)
    d.execute_script("clearInterval(window.__mover)")
    arrivals, latencies = d.execute_script(
        f"return [window.live.arrivals.slice({n_arr}), window.live.latencies.slice({n_lat})]")
    # Render times of the frames drawn in the window (the page keeps their numbers).
    render = d.execute_script(
        f"return window.live.frames.filter(f => f.frame > {first_frame}).map(f => f.frame_ms)")
    out = summarise(arrivals, latencies, [r for r in render if r is not None])
    out["moves"] = d.execute_script("return window.live.gazeSent")
    return out


def run_browser(url: str, seconds: float, mover: str = "page") -> dict:
    import live_browser
    reason = live_browser.missing()
    if reason is not None:
        return {"skipped": reason}
    b = live_browser.Browser(1280, 800)
    d = b.driver
    try:
        d.get(url)
        end = time.time() + 120
        while time.time() < end and not d.execute_script(
                "return window.live && window.live.received > 2"):
            time.sleep(0.1)
        res = {}
        for split in ("off", "uniform", "still"):
            res[split] = browser_phase(d, seconds, split, mover)
            res[split]["split"] = split
        return res
    finally:
        b.quit()


# -- the plain client -----------------------------------------------------------------------

def run_python(url: str, seconds: float) -> dict:
    from foveated_mi.live.client import run_measure
    res = {}
    for split in ("off", "uniform", "still"):
        r = run_measure(url, seconds, warmup=2.0, messages=[{"type": "view", "split": split}])
        r.pop("last", None)
        ft = r["frame_time_ms"]
        r["latency_frames_median"] = (r["latency_ms_median"] / ft) if ft and \
            r["latency_ms_median"] else math.nan
        res[split] = r
    return res


def fmt(v, f=".1f"):
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, f)


def main(argv=None) -> int:
    p = parser(__doc__, out_help="write the figures to this JSON file")
    p.add_argument("--json", dest="out", help="the same as --out")
    p.add_argument("--scene", default="voxel-city")
    p.add_argument("--size", type=int, nargs=2, default=[480, 270])
    p.add_argument("--preset", default="vr")
    p.add_argument("--spp", type=int, default=1)
    p.add_argument("--seconds", type=float, default=8.0, help="measured seconds per phase")
    p.add_argument("--client", choices=("browser", "python", "both"), default="both")
    p.add_argument("--mover", choices=("page", "driver"), default="page",
                   help="how the browser's mouse moves: events dispatched in the page, or "
                   "selenium's pointer actions through chromedriver")
    p.add_argument("--max-fps", type=float, default=60.0, dest="max_fps",
                   help="the server's frame cap (its default 60; 0: none)")
    args = p.parse_args(argv)
    args.variant = setup(args)        # the server renders with the same variant

    load_before = os.getloadavg()[0]
    proc, url = start_server(args)
    results: dict = {"scene": args.scene, "size": args.size, "preset": args.preset,
                     "spp": args.spp, "max_fps": args.max_fps, "cpu_count": os.cpu_count(),
                     "mover": args.mover}
    try:
        if args.client in ("browser", "both"):
            results["browser"] = run_browser(url, args.seconds, args.mover)
        if args.client in ("python", "both"):
            results["python"] = run_python(url, args.seconds)
    finally:
        stop_server(proc)
    tail = proc.stdout.read() + proc.stderr.read()
    m = re.search(r"stopped after (\d+) frames", tail)
    results["frames_rendered"] = int(m.group(1)) if m else None
    results["load_average_1min"] = [load_before, os.getloadavg()[0]]
    results["variant"] = args.variant

    print(f"live view, {args.scene} {args.size[0]}x{args.size[1]}, preset {args.preset}, "
          f"{args.spp} spp, {results['variant']}, {os.cpu_count()} cores, frame cap "
          f"{args.max_fps:g} fps, {args.seconds:g} s per row, browser mouse: {args.mover}, "
          f"load average {results['load_average_1min'][0]:.2f} before, "
          f"{results['load_average_1min'][1]:.2f} after")
    print("| client | split view | frames/s received | frame time ms | render ms (median) | "
          "gaze latency ms (median / p95) | latency in frame times |")
    print("|---|---|---|---|---|---|---|")
    for client in ("browser", "python"):
        res = results.get(client)
        if not res:
            continue
        if "skipped" in res:
            print(f"| {client} | skipped: {res['skipped']} | | | | | |")
            continue
        for split, r in res.items():
            print(f"| {client} | {split} | {fmt(r['fps'])} | {fmt(r['frame_time_ms'])} | "
                  f"{fmt(r['render_ms_median'])} | {fmt(r['latency_ms_median'], '.0f')} / "
                  f"{fmt(r['latency_ms_p95'], '.0f')} | {fmt(r['latency_frames_median'], '.2f')} |")
    for client in ("browser", "python"):
        r = (results.get(client) or {}).get("off")
        if r:
            ok_fps = r["fps"] >= TARGET_FPS
            ok_lat = r["latency_frames_median"] <= TARGET_LATENCY_FRAMES
            print(f"{client}: {fmt(r['fps'])} fps with the split view off: target >= "
                  f"{TARGET_FPS:g} {'met' if ok_fps else 'missed'}; median gaze latency "
                  f"{fmt(r['latency_frames_median'], '.2f')} frame times: target <= "
                  f"{TARGET_LATENCY_FRAMES:g} {'met' if ok_lat else 'missed'}")
    write_json(args.out, results, default=lambda v: None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
