"""The live view (`foveated-mi view`): the page in a real browser, the server's checks, the
recorded walk-through replayed by `foveated-mi sequence`, all at 64x36 films.

Browser tests drive Debian's chromium through selenium; without it they skip with one line
(scripts/setup.sh installs it as root). FOVEATED_MI_SCREENSHOT=PATH makes the screenshot
test write the page at 480x270 (voxel-city, split view) to PATH (docs/live_view.png).
"""
from __future__ import annotations

import http.client
import json
import math
import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("aiohttp", reason="the live view needs the 'view' extra (aiohttp)")

import live_browser  # noqa: E402
from foveated_mi.cli import main  # noqa: E402
from foveated_mi.live import protocol  # noqa: E402
from foveated_mi.live.display import display_u8, unpack  # noqa: E402
from foveated_mi.live.poses import Pose, PoseTrack  # noqa: E402
from foveated_mi.live.renderer import GazeInput  # noqa: E402
from foveated_mi.live.server import LiveView, check_bind  # noqa: E402
from foveated_mi.validate import ParameterError  # noqa: E402

W, H = 64, 36
#: The longest wait for something that takes milliseconds (a frame, a message, the loop
#: stopping): generous for a loaded machine; only an event that never comes reaches it.
WAIT_S = 30.0


def wait_for(fn, timeout=WAIT_S, what="condition"):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = fn()
        if v:
            return v
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    view = LiveView("cornell-box", size=(W, H), options={"preset": "vr"},
                    record_dir=str(tmp_path_factory.mktemp("walks")))
    yield view
    view.stop()
    assert not view.running


@pytest.fixture(scope="module")
def browser():
    reason = live_browser.missing()
    if reason is not None:
        pytest.skip(f"live view browser tests skipped: {reason}")
    b = live_browser.Browser()
    yield b.driver
    b.quit()


def _reset(live):
    r = live.renderer
    r.set_view(overlays=(), split="off", latency_ms=0.0)
    r.set_lock(False)
    r.set_gaze_source("mouse")
    r.home()


@pytest.fixture
def page(live, browser):
    """The page loaded, frames arriving; afterwards closed, and the loop stopped."""
    _reset(live)
    browser.get(live.url)
    wait_for(lambda: browser.execute_script("return window.live && window.live.received") >= 2,
             90, "the first frames")           # a cold kernel cache compiles them
    yield browser
    browser.get("about:blank")
    assert live.renderer.wait_stopped(WAIT_S)


def js(d, expr):
    return d.execute_script("return " + expr)


def meta(d):
    return js(d, "window.live.meta")


def canvas(d):
    return d.find_element("id", "view")


def move_mouse(d, u, v):
    """The mouse to film position (u, v) of the (left) panel, as a user would move it."""
    from selenium.webdriver.common.action_chains import ActionChains
    el = canvas(d)
    panels = meta(d)["panels"]
    w, h = el.size["width"], el.size["height"]
    x = int(round((u / panels - 0.5) * w))
    y = int(round((v - 0.5) * h))
    ActionChains(d, duration=0).move_to_element_with_offset(el, x, y).perform()


def key(d, name, seconds=0.0):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys
    k = {"right": Keys.ARROW_RIGHT, "home": Keys.HOME}.get(name, name)
    ActionChains(d).key_down(k).pause(seconds).key_up(k).perform()


def ring(d):
    """``(cx, r)`` of the fovea ring the page draws (read at once: it is redrawn per frame)."""
    return js(d, "(() => { const e = document.getElementById('fovea-ring'); "
                 "return [Number(e.getAttribute('cx')), Number(e.getAttribute('r'))]; })()")


def frames_after(d, n0):
    return js(d, f"window.live.frames.filter(f => f.frame > {n0})")


# -- the page -----------------------------------------------------------------------------

def test_page_loads_and_frames_arrive(page):
    m = wait_for(lambda: js(page, "window.live.received") >= 5 and meta(page), WAIT_S,
                 "5 frames")
    assert (m["width"], m["height"], m["panels"]) == (W, H, 1)
    assert 0.0 < m["ray_fraction"] <= 1.0 and m["frame_ms"] > 0 and m["rays"] > 0
    assert m["preset_resolved"] == "vr" and m["formation"] == "foveal"
    assert js(page, "document.getElementById('view').width") == W
    assert "fps shown" in page.find_element("id", "hud").text
    assert page.find_element("id", "conn").text == "connected"


def test_mouse_in_left_third_moves_gaze_and_fovea_ring(page):
    move_mouse(page, 0.85, 0.5)
    wait_for(lambda: meta(page)["gaze"][0] > 2 / 3, WAIT_S, "the gaze on the right")
    assert ring(page)[0] > 2 / 3 * W
    n0 = meta(page)["frame"]
    move_mouse(page, 1 / 6, 0.4)
    m = wait_for(lambda: meta(page)["gaze"][0] < 1 / 3 and meta(page), WAIT_S,
                 "the gaze on the left")
    assert m["frame"] > n0 and abs(m["gaze"][1] - 0.4) < 0.05
    cx, r = ring(page)
    assert cx < W / 3 and abs(cx - m["gaze"][0] * W) < 1e-3
    assert r == pytest.approx(m["fovea"]["px"])
    # Every later frame reports the new gaze too.
    wait_for(lambda: len(frames_after(page, m["frame"])) >= 3, WAIT_S, "three more frames")
    assert all(f["gaze"][0] < 1 / 3 for f in frames_after(page, m["frame"]))


def test_key_press_moves_and_turns_the_camera(page, live):
    before = meta(page)["camera"]
    key(page, "w", 0.3)
    m = wait_for(lambda: meta(page)["camera"]["origin"] != before["origin"] and meta(page),
                 WAIT_S, "the camera to move")
    o0, o1 = np.array(before["origin"]), np.array(m["camera"]["origin"])
    fwd = np.array(before["target"]) - o0
    step = o1 - o0
    assert float(step @ fwd) > 0.02 * live.renderer.camera.scale * np.linalg.norm(fwd)
    assert np.linalg.norm(np.cross(step, fwd)) <= 1e-6 * np.linalg.norm(step) * np.linalg.norm(fwd)
    before = meta(page)["camera"]
    key(page, "right", 0.2)
    m = wait_for(lambda: meta(page)["camera"]["target"] != before["target"] and meta(page),
                 WAIT_S, "the camera to turn")
    f0 = np.array(before["target"]) - np.array(before["origin"])
    f1 = np.array(m["camera"]["target"]) - np.array(m["camera"]["origin"])
    assert np.cross(f0, f1)[1] < 0        # y up: a turn to the right is clockwise seen from above
    assert not any(f["cut"] for f in js(page, "window.live.frames"))   # small moves: no cut


def test_history_resets_on_a_cut(live):
    """Small moves keep the history; going home from afar (the page's H key calls the same
    ``home``) or a jump is a cut, after which the frame starts afresh."""
    r = live.renderer
    assert r.wait_stopped(WAIT_S)
    _reset(live)
    r.render_frame()
    for _ in range(4):
        r.move(forward=0.01)
        m = r.render_frame().meta
    assert not m["cut"] and m["history_frame"] >= 3
    r.move(right=-2.0)                    # far from home
    r.render_frame()
    r.home()
    m = r.render_frame().meta
    assert m["cut"] and m["history_frame"] == 0
    m = r.render_frame().meta             # and the history builds up again
    assert not m["cut"] and m["history_frame"] == 1


def _shown(d):
    """Mean green excess of the shown frame (the traced overlay tints pixels green) and that
    frame's meta, read in one script: the page draws a frame and sets its meta in one task,
    so the two always belong to the same frame."""
    px, m = d.execute_script(
        "return [Array.from(document.getElementById('view').getContext('2d')"
        ".getImageData(0, 0, 64, 36).data), window.live.meta]")
    a = np.array(px, dtype=float).reshape(-1, 4)
    return float(np.mean(a[:, 1] - 0.5 * (a[:, 0] + a[:, 2]))), m


def _green(d):
    return _shown(d)[0]


def test_an_overlay_toggles(page):
    g0 = _green(page)
    page.find_element("id", "ov-traced").click()
    g, m = wait_for(lambda: (s := _shown(page)) and "traced" in s[1]["overlays"] and s,
                    WAIT_S, "the overlay")
    assert js(page, "window.live.state.overlays") == ["traced"]
    # Each traced pixel tinted 60 % toward (40, 255, 90) gains about 0.6 * (255 - 65) = 114
    # of green excess; a settled still view traces a turn of its rays (foveal_still_spp),
    # so the rise follows the shown frame's rays: at least a quarter of that, for the scene's
    # own green wall and the frames that differ.
    assert m["rays"] > 0
    assert g - g0 > 0.25 * 114.0 * m["rays"] / (W * H)
    page.find_element("id", "ov-traced").click()
    wait_for(lambda: meta(page)["overlays"] == [] and meta(page)["frame"] > m["frame"],
             WAIT_S, "the overlay off")
    assert _green(page) < g0 + 2.0
    # The rings are the page's own: hidden at once, no frame needed.
    assert js(page, "document.getElementById('rings').style.display") == ""
    page.find_element("id", "ov-rings").click()
    assert js(page, "document.getElementById('rings').style.display") == "none"
    page.find_element("id", "ov-rings").click()
    assert js(page, "document.getElementById('rings').style.display") == ""


def test_a_preset_change_takes_effect_and_a_bad_value_is_refused(page, capsys):
    from selenium.webdriver.support.ui import Select
    Select(page.find_element("id", "preset")).select_by_value("guided")
    page.find_element("id", "apply").click()
    m = wait_for(lambda: meta(page)["preset_resolved"] == "guided" and meta(page), 90,
                 "the guided preset")
    assert m["formation"] == "film" and m["denoiser"] == "svgf"
    rebuild = wait_for(lambda: js(page, "window.live.rebuild"), WAIT_S, "the rebuild report")
    assert rebuild["changed"] == {"preset": "guided"} and rebuild["ms"] > 0
    assert "rebuilt in" in page.find_element("id", "rebuild").text
    # A bad value: refused with the command line's own line, nothing changes.
    box = page.find_element("id", "ray_budget")
    box.clear()
    box.send_keys("2")
    page.find_element("id", "apply").click()
    text = wait_for(lambda: page.find_element("id", "error").text, WAIT_S, "the error line")
    assert main(["view", "cornell-box", "--ray-budget", "2"]) == 2
    cli_line = capsys.readouterr().err.strip()
    assert text == cli_line and text.startswith("foveated-mi: error: ray_budget = 2.0 is invalid")
    assert meta(page)["ray_budget"] == 0.1
    Select(page.find_element("id", "preset")).select_by_value("vr")
    box.clear()
    box.send_keys("0.1")
    page.find_element("id", "apply").click()
    wait_for(lambda: meta(page)["preset_resolved"] == "vr", 90, "the vr preset back")


def test_the_page_sets_a_frame_rate_target_and_shows_the_budget_held(page):
    from selenium.webdriver.support.ui import Select
    Select(page.find_element("id", "fps")).select_by_value("90")
    m = wait_for(lambda: (m := meta(page))["frame_budget"] and m, 90, "the 90 Hz budget")
    assert m["frame_budget"]["budget_ms"] == 1000.0 / 90
    assert js(page, "window.live.state.frame_ms") == 1000.0 / 90
    # The line and the frame it describes, read in one script (the page sets both in one
    # task): the target, the render time against the budget, the rung chosen, the rate held.
    b, text = js(page, "[window.live.meta.frame_budget, "
                       "document.getElementById('budget').textContent]")
    assert text == (f"90 Hz target: {b['measured_ms']:.1f} of {b['budget_ms']:.1f} ms (rung "
                    f"{b['rung']}: {b['spp']} spp, {100 * b['ray_budget']:.0f} % rays) · held "
                    f"{b['held']}/{b['window_frames']} frames of the last second")
    assert 1 <= b["window_frames"] and 0 <= b["held"] <= b["window_frames"]
    Select(page.find_element("id", "fps")).select_by_value("0")
    wait_for(lambda: meta(page)["frame_budget"] is None, 90, "the target off")
    assert page.find_element("id", "budget").text == ""
    assert js(page, "window.live.state.frame_ms") == 0.0


def test_split_view_shows_uniform_rendering_with_the_same_rays(page):
    from selenium.webdriver.support.ui import Select
    Select(page.find_element("id", "split")).select_by_value("uniform")
    m = wait_for(lambda: meta(page)["panels"] == 2 and meta(page), 60, "the split view")
    w, h = m["split_info"]["size"]
    assert w * h == pytest.approx(0.1 * W * H, rel=0.25) and m["split_info"]["ms"] > 0
    assert js(page, "document.getElementById('view').width") == 2 * W
    assert "uniform, same rays" in page.find_element("id", "label-right").text


def test_gaze_lock_holds_the_gaze_while_the_mouse_moves(page):
    move_mouse(page, 0.25, 0.5)
    held = wait_for(lambda: abs(meta(page)["gaze"][0] - 0.25) < 0.03 and meta(page)["gaze"],
                    WAIT_S, "the gaze at the left")
    key(page, "l")
    wait_for(lambda: meta(page)["locked"], WAIT_S, "the lock")
    n0 = meta(page)["frame"]
    for u in (0.5, 0.7, 0.9):
        move_mouse(page, u, 0.3)
        time.sleep(0.05)
    wait_for(lambda: len(frames_after(page, n0)) >= 5, WAIT_S, "frames while locked")
    assert all(f["gaze"] == held for f in frames_after(page, n0))
    key(page, "l")
    move_mouse(page, 0.8, 0.3)
    wait_for(lambda: meta(page)["gaze"][0] > 0.7, WAIT_S, "the gaze free again")


def test_closing_the_tab_stops_the_loop(live, browser):
    _reset(live)
    first = browser.current_window_handle
    browser.switch_to.new_window("tab")
    browser.get(live.url)
    wait_for(lambda: browser.execute_script("return window.live.received") >= 3, 60, "frames")
    move_mouse(browser, 0.4, 0.4)
    assert live.renderer.active
    browser.close()
    browser.switch_to.window(first)
    assert live.renderer.wait_stopped(WAIT_S), "the loop still renders with no page open"
    n = live.renderer.frames_rendered
    time.sleep(0.5)
    assert live.renderer.frames_rendered == n
    status = json.loads(_get(live, "/status?token=" + live.token)[2])
    assert status["frames_rendered"] == n and status["viewers"] == 0 and not status["active"]


def test_recorded_walkthrough_replays_through_sequence(page, live, tmp_path):
    page.find_element("id", "record").click()
    wait_for(lambda: js(page, "window.live.state.recording"), WAIT_S, "recording")
    home = meta(page)["camera"]
    for u, v in ((0.3, 0.4), (0.6, 0.6), (0.45, 0.3)):
        move_mouse(page, u, v)
        time.sleep(0.05)
    from selenium.webdriver.common.action_chains import ActionChains
    ActionChains(page).key_down("w").perform()        # held until the camera has moved
    try:
        wait_for(lambda: meta(page)["camera"] != home, WAIT_S, "the camera to move")
    finally:
        ActionChains(page).key_up("w").perform()
    n0 = meta(page)["frame"]
    key(page, "h")                        # a jump: a cut in the recording
    move_mouse(page, 0.7, 0.5)
    # Frames come at the machine's pace: stop once a frame back home (the cut is the first
    # of them) and five before it were recorded.
    wait_for(lambda: (m := meta(page))["frame"] > n0 and m["camera"] == home
             and (m["recording"] or 0) >= 5, WAIT_S, "the cut and five frames recorded")
    page.find_element("id", "record").click()
    rec = wait_for(lambda: js(page, "window.live.recording"), WAIT_S, "the recording")
    assert os.path.isfile(rec["toml_path"]) and os.path.isfile(rec["csv_path"])
    assert rec["toml_name"] in page.find_element("id", "recording").text
    track = PoseTrack.read(rec["csv_path"])
    assert len(track) == rec["frames"] >= 5
    assert any(track.cut_before(i) for i in range(len(track)))
    out = tmp_path / "replay"
    with live.paused():                   # the page stays open; its frames wait
        n = live.renderer.frames_rendered
        assert main(["sequence", rec["toml_path"], "--out", str(out), "--no-progress"]) == 0
        assert live.renderer.frames_rendered == n
    stats = [json.loads(line) for line in (out / "stats.jsonl").read_text().splitlines()]
    assert len(stats) == len(track)
    for i, s in enumerate(stats):
        p = track[i]
        assert tuple(s["gaze"]) == p.gaze, i
        assert s["camera"] == p.camera, i
        assert s["rays"] == p.rays, i         # the same sampling, frame by frame
    assert (out / "sequence.mp4").stat().st_size > 0


def test_a_second_page_shares_the_renderer_or_is_refused(page, live):
    from foveated_mi.live.client import run_measure
    n0 = js(page, "window.live.received")
    shared = run_measure(live.url, WAIT_S, warmup=0.2, frames=2)
    assert shared["frames"] == 2 and not shared["errors"]
    wait_for(lambda: js(page, "window.live.received") > n0, WAIT_S, "the page's frames")
    live.server.max_viewers = 1
    try:        # the server refuses and closes: the client ends there, not at WAIT_S
        refused = run_measure(live.url, WAIT_S, warmup=0.0)
    finally:
        live.server.max_viewers = 4
    assert refused["frames"] == 0
    assert refused["errors"] and "refused" in refused["errors"][0]


def test_screenshot_of_the_page(live, browser, tmp_path):
    """The page with the split view and rings; FOVEATED_MI_SCREENSHOT=PATH writes the
    documentation's screenshot (voxel-city, 480x270) there."""
    from selenium.webdriver.support.ui import Select
    target = os.environ.get("FOVEATED_MI_SCREENSHOT")
    view = live
    if target:
        view = LiveView("voxel-city", size=(480, 270), options={"preset": "vr"})
    try:
        _reset(view)
        browser.set_window_size(1280, 720)
        browser.get(view.url)
        wait_for(lambda: browser.execute_script("return window.live.received") >= 2, 60,
                 "frames")
        Select(browser.find_element("id", "split")).select_by_value("uniform")
        browser.find_element("id", "ov-map").click()
        wait_for(lambda: meta(browser)["panels"] == 2 and "map" in meta(browser)["overlays"],
                 30, "the split view with the map")
        move_mouse(browser, 0.38, 0.55)
        wait_for(lambda: abs(meta(browser)["gaze"][0] - 0.38) < 0.02, WAIT_S, "the gaze")
        time.sleep(0.5)
        path = target or str(tmp_path / "live_view.png")
        assert browser.save_screenshot(path)
    finally:
        browser.get("about:blank")
        browser.set_window_size(1200, 760)
        if target:
            view.stop()
        assert live.renderer.wait_stopped(WAIT_S)
    from PIL import Image
    img = np.asarray(Image.open(path).convert("RGB"))
    assert img.shape[1] >= 1000 and img.std() > 10      # a page, not a blank window


# -- the server's checks (no browser) -----------------------------------------------------

def _get(live, path, headers=None):
    c = http.client.HTTPConnection("127.0.0.1", live.port, timeout=WAIT_S)
    c.request("GET", path, headers=headers or {})
    r = c.getresponse()
    body = r.read().decode(errors="replace")
    c.close()
    return r.status, dict(r.getheaders()), body


def _upgrade_headers(origin=None, host=None, port=0):
    h = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
         "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ==",
         "Host": host or f"127.0.0.1:{port}"}
    if origin:
        h["Origin"] = origin
    return h


def test_foreign_origin_host_and_token_are_refused(live):
    tok = "?token=" + live.token
    p = live.port
    assert _get(live, "/" + tok)[0] == 200
    assert _get(live, "/" + tok, {"Host": f"localhost:{p}"})[0] == 200
    status, headers, _ = _get(live, "/" + tok)
    assert "default-src 'self'" in headers["Content-Security-Policy"]
    # DNS rebinding: a name that resolves here, but not this server's name.
    assert _get(live, "/" + tok, {"Host": f"attacker.example:{p}"})[0] == 403
    assert _get(live, "/" + tok, {"Host": f"127.0.0.1:{p + 1}"})[0] == 403
    assert _get(live, "/")[0] == 403 and _get(live, "/?token=wrong")[0] == 403
    # The socket: another origin, a foreign Host, no token: refused before the upgrade.
    ws = "/ws" + tok
    assert _get(live, ws, _upgrade_headers("http://attacker.example", port=p))[0] == 403
    assert _get(live, ws, _upgrade_headers(f"http://127.0.0.1:{p + 1}", port=p))[0] == 403
    assert _get(live, ws, _upgrade_headers(f"http://attacker.example:{p}",
                                           host=f"attacker.example:{p}", port=p))[0] == 403
    assert _get(live, "/ws", _upgrade_headers(f"http://127.0.0.1:{p}", port=p))[0] == 403
    assert _get(live, ws, _upgrade_headers(f"http://127.0.0.1:{p}", port=p))[0] == 101
    c = http.client.HTTPConnection("127.0.0.1", p, timeout=WAIT_S)
    c.request("POST", "/" + tok, body="x")
    assert c.getresponse().status == 405
    c.close()
    assert live.renderer.wait_stopped(WAIT_S)


def test_a_non_local_bind_needs_the_flag(capsys):
    assert main(["view", "cornell-box", "--host", "0.0.0.0", "--port", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["foveated-mi: error: --host = '0.0.0.0' is invalid: expected a loopback "
                   "address (127.0.0.1, ::1 or localhost); another interface needs "
                   "--allow-remote"]
    assert "warning" in check_bind("0.0.0.0", allow_remote=True)
    assert check_bind("127.0.0.1") is None and check_bind("::1") is None
    with pytest.raises(ParameterError):
        check_bind("192.168.1.20")


def _free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def test_a_scene_that_fails_gives_one_line_exit_2_and_serves_nothing(tmp_path, capsys):
    port = _free_port()
    env = dict(os.environ)
    r = subprocess.run([sys.executable, "-m", "foveated_mi.cli", "view", "no-such-scene",
                        "--port", str(port)], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "foveated-mi: error: scene = 'no-such-scene' is invalid: expected one of")
    assert r.stdout == ""                 # no address printed
    with pytest.raises(OSError):          # and nothing listens
        socket.create_connection(("127.0.0.1", port), timeout=1).close()
    bad = tmp_path / "broken.xml"
    bad.write_text('<scene version="3.0.0"><shape type="nonexistent_plugin"/></scene>')
    assert main(["view", str(bad), "--port", str(port)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"foveated-mi: error: scene = '{bad}'")


def test_messages_are_a_fixed_validated_set():
    assert protocol.parse('{"type": "gaze", "x": 0.2, "y": 0.3, "seq": 4}') == (
        "gaze", {"x": 0.2, "y": 0.3, "seq": 4})
    assert protocol.parse('{"type": "settings", "spp": "2"}')[1] == {"spp": 2}
    bad = ['{"type": "eval", "code": "1"}', '{"type": "gaze", "x": NaN, "y": 0}',
           '{"type": "gaze", "x": 0.5}', '{"type": "gaze", "x": 0.5, "y": 0.5, "z": 1}',
           '{"type": "move", "yaw": 1000}', '{"type": "view", "overlays": ["exec"]}',
           '{"type": "view", "split": "tv"}', '{"type": "settings"}',
           '{"type": "settings", "spp": 0}', '{"type": "lock", "on": 1}', "[1, 2]", "nope",
           b'{"type": "home"}', '{"type": "gaze_source", "source": "url"}',
           '{"type": "view", "latency_ms": -5}', "x" * (protocol.MAX_MESSAGE_BYTES + 1)]
    for text in bad:
        with pytest.raises(ParameterError) as e:
            protocol.parse(text)
        assert "\n" not in str(e.value) and "is invalid: expected" in str(e.value)
    with pytest.raises(ParameterError, match=r"^--spp = 0 is invalid"):
        protocol.parse('{"type": "settings", "spp": 0}')


def test_bad_messages_get_one_line_and_the_socket_stays_open(live):
    import asyncio
    import aiohttp

    async def talk():
        async with aiohttp.ClientSession() as s:
            async with s.ws_connect(f"ws://127.0.0.1:{live.port}/ws?token={live.token}") as ws:
                state = json.loads((await ws.receive(timeout=WAIT_S)).data)
                assert state["type"] == "state" and state["width"] == W
                replies = []
                csv = json.dumps({"type": "gaze_source", "source": "csv",
                                  "name": "../../secret/walk.csv", "csv": "t,x,y\n0,0.5\n"})
                for m in ('{"type": "shell", "cmd": "ls"}', '{"type": "settings", '
                          '"preset": "fast"}', '{"type": "view", "latency_ms": 5000}', csv):
                    await ws.send_str(m)
                    while True:
                        msg = await ws.receive(timeout=WAIT_S)
                        if msg.type == aiohttp.WSMsgType.TEXT and \
                                json.loads(msg.data)["type"] == "error":
                            replies.append(json.loads(msg.data)["message"])
                            break
                        if msg.type == aiohttp.WSMsgType.BINARY:
                            await ws.send_str(json.dumps({"type": "ack",
                                                          "frame": unpack(msg.data)[0]["frame"]}))
                return replies, ws.closed
    replies, closed = asyncio.run(talk())
    assert not closed
    assert replies[0].startswith("foveated-mi: error: type = 'shell' is invalid")
    assert replies[1].startswith("foveated-mi: error: preset = 'fast' is invalid: expected one of")
    assert replies[2] == ("foveated-mi: error: latency_ms = 5000 is invalid: expected a finite "
                          "number >= 0 and <= 1000")
    assert replies[3].startswith("foveated-mi: error: walk.csv:2 = '0,0.5' is invalid")
    assert live.renderer.wait_stopped(WAIT_S)


def test_python_client_measures_rate_and_latency(live):
    """Counted, not timed: the client stops at 10 frames after its warm-up, and its rate is
    those frames over the time they took (a speed figure: benchmarks/bench_live_view.py)."""
    from foveated_mi.live.client import run_measure
    _reset(live)
    r = run_measure(live.url, WAIT_S, warmup=0.2, frames=10)
    assert r["frames"] == 10 and not r["errors"]
    assert r["seconds"] > 0 and r["fps"] == (r["frames"] - 1) / r["seconds"]
    # The gaze moves at 60 Hz and every frame renders the newest one: of 10 frames, some
    # render a gaze sent after the warm-up, each giving a latency.
    assert r["latency_samples"] > 0 and r["latency_ms_median"] > 0
    assert r["last"]["gaze_seq"] > 0 and r["last"]["gaze_age_ms"] is not None
    with pytest.raises(ParameterError, match=r"^frames = 1 is invalid: expected an integer >= 2"):
        run_measure(live.url, WAIT_S, frames=1)
    assert live.renderer.wait_stopped(WAIT_S)


# -- the renderer's inputs (no browser, no server thread) ----------------------------------

def test_latency_renders_the_gaze_of_that_many_ms_ago(live):
    g = GazeInput()
    g.add(10.0, 0.1, 0.1, 1)
    g.add(10.2, 0.9, 0.9, 2)
    assert g.at(10.1)[:3] == (0.1, 0.1, 1) and g.at(10.25)[:3] == (0.9, 0.9, 2)
    assert g.at(9.0)[:3] == (0.5, 0.5, 0)
    r = live.renderer
    assert r.wait_stopped(WAIT_S)
    _reset(live)
    # A clock the test moves: the gaze samples and the frames are 350 ms apart whatever
    # the machine's load, against a 300 ms latency.
    t0 = time.perf_counter()
    now = [t0]
    r.set_view(latency_ms=300.0)
    r.clock = lambda: now[0]
    try:
        r.set_gaze(0.2, 0.3, 101)
        now[0] += 0.35
        r.set_gaze(0.8, 0.7, 102)
        m = r.render_frame().meta
        assert m["gaze"] == [0.2, 0.3] and m["gaze_seq"] == 101 and m["latency_ms"] == 300.0
        # (t0 + 0.35) - t0 in ms: the sum rounds by half an ulp of t0 + 0.35, the product
        # by less, so within one ulp (s) times 1e3.
        assert abs(m["gaze_age_ms"] - 350.0) <= 1e3 * math.ulp(t0 + 0.35)
        now[0] += 0.35
        assert r.render_frame().meta["gaze"] == [0.8, 0.7]
    finally:
        r.clock = time.perf_counter
        r.set_view(latency_ms=0.0)


def test_a_frame_rate_target_puts_its_budget_in_each_frame_and_changes_live(live):
    """Both clocks are the test's: the renderer's (the last second's window) and the frame
    budget's (a frame's render time, read once as it starts and once as it ends)."""
    from foveated_mi.live.renderer import LiveRenderer
    assert live.renderer.wait_stopped(WAIT_S)
    r = LiveRenderer(live.renderer.scene, options={"preset": "vr", "fps": 90})
    now, t, step = [100.0], [0.0], [10.5e-3]
    r.clock = lambda: now[0]

    def render_clock():
        t[0] += step[0]
        return t[0]
    r.integ._budget.value.clock = render_clock

    def frame(dt=0.1):
        now[0] += dt
        m = r.render_frame().meta
        return m, m["frame_budget"]

    for _ in range(3):
        m, b = frame()
    # 1000 / 90 and its reciprocal: each a correctly rounded division.
    assert b["budget_ms"] == 1000.0 / 90 and math.isclose(b["fps"], 90.0, rel_tol=4e-16)
    # A difference of two clock readings below 1 s: exact to an ulp of the later one.
    assert abs(b["measured_ms"] - 10.5) <= 1e3 * math.ulp(t[0])
    # 10.5 ms of 11.1 holds the cheapest rung: the next one is predicted dearer than 90 % of
    # the budget (its samples double, cost model section of foveated_mi.budget).
    assert (b["rung"], b["spp"], b["ray_budget"], b["ladder"]) == (0, 2, 0.1, "still")
    assert (b["held"], b["window_frames"]) == (3, 3) and b["predicted_ms"] is not None
    # Live: the next frame holds 120 Hz; 10.5 ms misses it, and only the new target's frames count.
    r.change_settings({"fps": 120})
    m, b = frame()
    assert m["rebuild"]["changed"] == {"fps": 120} and b["budget_ms"] == 1000.0 / 120
    assert (b["held"], b["window_frames"]) == (0, 1)
    step[0] = 5e-3
    m, b = frame()
    assert (b["held"], b["window_frames"]) == (1, 2)
    m, b = frame(1.5)                     # the earlier frames are out of the last second
    assert (b["held"], b["window_frames"]) == (1, 1)
    # A frame_ms turns the fps given off (and the other way round); 0 turns the target off.
    r.change_settings({"frame_ms": 20.0})
    assert frame()[1]["budget_ms"] == 20.0 and r._given["fps"] == 0.0
    assert r.check_settings({"fps": 90})[0]["frame_ms"] == 0.0
    # Bad values: the option's own line; a preset without the foveal buffer refuses a target.
    with pytest.raises(ParameterError, match=r"^fps = -1.0 is invalid: expected a finite "):
        r.check_settings({"fps": -1.0})
    with pytest.raises(ParameterError, match=r"^frame_ms = 20.0 is invalid: expected 0 unless "
                       r"formation = 'foveal'"):
        r.check_settings({"preset": "guided"})
    assert protocol.parse('{"type": "settings", "fps": "72"}')[1] == {"fps": 72.0}
    with pytest.raises(ParameterError, match=r"^fps = 'fast' is invalid: expected a finite"):
        protocol.parse('{"type": "settings", "fps": "fast"}')
    r.change_settings({"fps": 0})
    assert frame()[1] is None and r.state()["frame_ms"] == 0.0


def test_a_bad_frame_rate_target_is_one_line_and_exit_2(capsys):
    # --port 70000: were a target not refused, the command would stop at the port, not serve.
    for args, line in (
            (["--fps", "-5"], "fps = -5.0 is invalid: expected a finite number >= 0 and <= 1e+06"),
            (["--preset", "guided", "--fps", "90"], "frame_ms = 11.11111111111111 is invalid: "
             "expected 0 unless formation = 'foveal' and foveal_space = 'buffer'"),
            (["--fps", "90", "--frame-ms", "20"], "fps = 90.0 is invalid: expected 1000 / "
             "frame_ms (50)")):
        assert main(["view", "cornell-box", "--port", "70000", *args]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("foveated-mi: error: " + line), err


def test_gaze_replay_sources_and_a_bad_csv(live, tmp_path):
    r = live.renderer
    assert r.wait_stopped(WAIT_S)
    r.set_gaze_source("saccades")
    seen = set()
    for _ in range(12):
        seen.add(tuple(r.render_frame().meta["gaze"]))
        time.sleep(0.04)
    assert len(seen) >= 2                   # the model moved the gaze on its own
    with pytest.raises(ParameterError) as e:
        r.set_gaze_source("csv", "t,x,y\n0,0.5,0.5\n0.1,nan,0.5\n", "mine.csv")
    assert str(e.value).startswith("mine.csv:3 = '0.1,nan,0.5' is invalid")
    r.set_gaze_source("csv", "t,x,y\n100.0,0.25,0.75\n", "mine.csv")
    assert r.render_frame().meta["gaze"] == [0.25, 0.75]
    r.set_gaze_source("mouse")


def test_still_split_converges_while_the_camera_rests(live):
    r = live.renderer
    assert r.wait_stopped(WAIT_S)
    _reset(live)
    r.set_view(split="still")
    try:
            # The still gets the foveated frames' time: a cold kernel cache's first frames spend
        # it compiling, so it may take a few frames to add samples.
        spp = [r.render_frame().meta["split_info"]["spp"]]
        while spp[-1] <= spp[0] and len(spp) < 1000:
            spp.append(r.render_frame().meta["split_info"]["spp"])
        spp += [r.render_frame().meta["split_info"]["spp"] for _ in range(3)]
        assert spp[0] >= 1 and spp[-1] > spp[0] and spp == sorted(spp)
        r.move(forward=0.05)      # the camera moved: the still starts again
        assert r.render_frame().meta["split_info"]["spp"] < spp[-1]
    finally:
        r.set_view(split="off")


@pytest.mark.parametrize("preset", ["vr", "guided"])
def test_every_overlay_draws_for_both_formations(live, preset):
    """The buffer overlays on the foveated buffer's samples (vr) and on the film (guided)."""
    from foveated_mi.live.renderer import LiveRenderer
    assert live.renderer.wait_stopped(WAIT_S)
    r = LiveRenderer(live.renderer.scene, options={"preset": preset})
    for _ in range(3):
        frame = r.render_frame()
    gaze = tuple(frame.meta["gaze"])
    for name in ("map", "history", "traced"):
        img = frame.image.copy()
        r._draw_overlays(img, (name,), {}, gaze)
        assert np.abs(img.astype(int) - frame.image).mean() > 1.0, (preset, name)
    assert not r._overlay_failed


def test_moving_gaze_and_camera_compile_nothing_after_warm_up(live):
    """Per-frame values reach Dr.Jit as opaque values: frames whose gaze and camera move,
    with the overlays and the uniform split view on, compile no kernel after the first."""
    from kernel_counts import compiled_by
    r = live.renderer
    assert r.wait_stopped(WAIT_S)
    _reset(live)
    step = [0]

    def frames(n):
        for _ in range(n):
            step[0] += 1
            r.set_gaze(0.3 + 0.02 * (step[0] % 20), 0.5, 1000 + step[0])
            r.move(forward=0.01, yaw=0.5)
            r.render_frame()
    try:
        for split, overlays in (("off", ()), ("uniform", ("map", "history", "traced"))):
            r.set_view(split=split, overlays=overlays)
            # The warm-up runs with the kernel history on as well: with it turned on, and a
            # cold kernel cache, one kernel of the first frames was seen compiled again a few
            # frames later (a warm cache finds it); frames after that compile nothing.
            compiled_by(lambda: frames(3))
            assert compiled_by(lambda: frames(5)) == 0, (split, overlays)
    finally:
        _reset(live)


# -- poses, config, display ---------------------------------------------------------------

def test_pose_csv_round_trip_and_one_line_errors(tmp_path):
    cam = {"origin": [0.1, 0.2, 3.9], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
           "fov": 39.3}
    track = PoseTrack([Pose(0.0, (0.1 / 3, 0.5), cam), Pose(0.0166, (0.7, 1 / 7), cam, True,
                                                            1.5, 230)])
    path = tmp_path / "walk.csv"
    track.write(path)
    back = PoseTrack.read(path)
    assert [p.gaze for p in back] == [p.gaze for p in track]         # exact
    assert back.camera(1) == cam and back.cut_before(1) and not back.cut_before(0)
    header = path.read_text().splitlines()[0]
    row = path.read_text().splitlines()[2].split(",")
    cols = header.split(",")

    def with_value(col, value):
        r = list(row)
        r[cols.index(col)] = value
        return header + "\n" + path.read_text().splitlines()[1] + "\n" + ",".join(r) + "\n"
    for col, value, expected in (("gaze_x", "nan", "walk.csv:3: gaze_x = 'nan' is invalid"),
                                 ("t", "-1", "walk.csv:3: t = '-1' is invalid: expected a "
                                  "time > 0.0"),
                                 ("fov", "180", "walk.csv:3: fov = '180' is invalid"),
                                 ("cut", "yes", "walk.csv:3: cut = 'yes' is invalid"),
                                 ("up_y", "0", "walk.csv:3: camera.up")):
        with pytest.raises(ParameterError) as e:
            PoseTrack.parse(with_value(col, value), "walk.csv")
        assert str(e.value).startswith(expected) and "\n" not in str(e.value), str(e.value)
    with pytest.raises(ParameterError, match="all ten camera columns or none"):
        PoseTrack.parse("t,gaze_x,gaze_y,fov\n0,0.5,0.5,40\n", "p.csv")
    with pytest.raises(ParameterError, match=r"^p.csv:1 = 't,gaze_x,gaze_y,tilt'"):
        PoseTrack.parse("t,gaze_x,gaze_y,tilt\n0,0.5,0.5,1\n", "p.csv")


def test_sequence_config_takes_per_frame_poses(tmp_path, capsys):
    from foveated_mi.config import load_config
    (tmp_path / "p.csv").write_text("t,gaze_x,gaze_y,cut\n0,0.2,0.3,0\n0.05,0.4,0.5,1\n"
                                    "0.1,0.6,0.7,0\n")
    base = 'scene = "cornell-box"\nsize = [64, 36]\n[poses]\npath = "p.csv"\n'
    (tmp_path / "a.toml").write_text(base)
    cfg = load_config(tmp_path / "a.toml")
    assert cfg.frames == 3 and cfg.gaze_at(2) == (0.6, 0.7) and cfg.camera_at(1) is None
    assert cfg.cut_before(1) and not cfg.cut_before(2) and cfg.time(2) == pytest.approx(0.1)
    for extra, expected in (('[gaze]\ntype = "fixed"\n', "gaze = {'type': 'fixed'} is invalid: "
                             "expected no [camera] or [gaze] beside [poses]"),
                            ("", "frames = 4 is invalid: expected an integer >= 1 and <= 3")):
        text = ("frames = 4\n" if not extra else "") + base + extra
        (tmp_path / "b.toml").write_text(text)
        assert main(["sequence", str(tmp_path / "b.toml"), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and expected in err[0], err
    (tmp_path / "p.csv").write_text("t,gaze_x,gaze_y\n0,0.2,0.3\n0,0.4,0.5\n")
    assert main(["sequence", str(tmp_path / "a.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("foveated-mi: error: p.csv:3: t = '0' is invalid: expected a time > 0")


def test_display_conversion_matches_to_display():
    from foveated_mi.render import to_display
    rng = np.random.default_rng(1)
    x = (rng.random((36, 64, 3)) ** 4 * 30).astype(np.float32)
    x[0, 0] = [np.nan, np.inf, -1.0]
    for exposure in (0.0, -1.5, 2.0):
        ref = np.round(255 * to_display(x, exposure)).astype(int)
        assert np.abs(display_u8(x, exposure).astype(int) - ref).max() <= 1
