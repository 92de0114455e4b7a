"""The live view's web server (aiohttp) and :class:`LiveView`, which runs it in a thread.

Routes: ``/`` the page (``static/index.html``), ``/live.js`` and ``/live.css`` its script
and style, ``/ws`` the page's WebSocket, ``/status`` the loop's counters (JSON). Nothing
else, and nothing but ``GET``.

**Who may connect.** The server binds 127.0.0.1 unless told otherwise; another interface
needs ``allow_remote`` (the command line's ``--allow-remote``), prints a warning and turns
the token on. Every request's ``Host`` must name this server (a loopback name or, with
``allow_remote``, an IP address) at its port, which defeats DNS rebinding; a WebSocket
whose ``Origin`` is not the page's own is refused; with a token (``--token``, always in a
notebook and with ``allow_remote``), the page and the socket need ``?token=`` (compared in
constant time). A page's messages are a fixed set of validated types
(:mod:`foveated_mi.live.protocol`); nothing it sends is run.

**Pages.** Up to :attr:`LiveServer.max_viewers` pages share the renderer (every page shows
the same frames; the last input wins); one more is refused with a message. Each page gets
the newest frame when it has fewer than ``max_inflight`` frames unacknowledged, so a slow
page drops frames instead of queueing them. When the last page closes, the loop stops.
"""
from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
import os
import secrets
import sys
import threading
import time
from typing import Any

from ..validate import ParameterError
from . import protocol

log = logging.getLogger(__name__)

__all__ = ["LiveServer", "LiveView", "check_bind", "LOOPBACK_NAMES"]

STATIC = os.path.join(os.path.dirname(__file__), "static")
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
_CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css"}
_PAGES = {"/": "index.html", "/index.html": "index.html", "/live.js": "live.js",
          "/live.css": "live.css"}


def _is_loopback(host: str) -> bool:
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_bind(host: str, allow_remote: bool = False) -> str | None:
    """Check the address to bind; returns a warning line for another interface (allowed
    only with ``allow_remote``), None for a loopback address."""
    if not isinstance(host, str) or not host:
        raise ParameterError("--host", host, "an address to bind, such as 127.0.0.1")
    if _is_loopback(host):
        return None
    if not allow_remote:
        raise ParameterError("--host", host, "a loopback address (127.0.0.1, ::1 or "
                             "localhost); another interface needs --allow-remote")
    return (f"foveated-mi: warning: serving on {host}, reachable from other machines: anyone "
            "who has the address and its token can steer this renderer")


def _split_host(value: str) -> tuple[str, int | None]:
    """``(hostname, port)`` of a Host header (``[::1]:8765`` -> ``::1``, 8765)."""
    value = value.strip().lower()
    if value.startswith("["):
        end = value.find("]")
        if end < 0:
            return value, None
        name, rest = value[1:end], value[end + 1:]
        port = rest[1:] if rest.startswith(":") else None
    else:
        name, _, port = value.partition(":")
        port = port or None
    try:
        return name, (int(port) if port is not None else None)
    except ValueError:
        return name, -1


class _Viewer:
    """One connected page: its socket, the frames sent and not yet acknowledged."""

    def __init__(self, ws):
        self.ws = ws
        self.wake = asyncio.Event()
        self.unacked: list[int] = []
        self.last_sent = -1
        self.sent_at = 0.0


class LiveServer:
    """The aiohttp application around a :class:`~foveated_mi.live.renderer.LiveRenderer`."""

    max_viewers = 4
    max_inflight = 2

    def __init__(self, renderer, *, host: str = "127.0.0.1", port: int = 8765,
                 token: str | None = None, allow_remote: bool = False):
        self.renderer = renderer
        self.host, self.port = host, port
        self.token = token
        self.allow_remote = allow_remote
        self.viewers: list[_Viewer] = []
        self.loop: asyncio.AbstractEventLoop | None = None
        self._latest = None
        self._latest_sent = True
        self._runner = None
        self.refused = 0
        renderer.publish = self._publish_threadsafe
        renderer.on_error = self._error_threadsafe
        renderer.throttled = self._saturated

    # -- lifecycle ------------------------------------------------------------------------
    async def start(self) -> int:
        """Bind and serve; returns the port (a free one for ``port = 0``)."""
        from aiohttp import web
        self.loop = asyncio.get_running_loop()
        app = web.Application(middlewares=[self._guard],
                              client_max_size=protocol.MAX_MESSAGE_BYTES)
        app.router.add_get("/", self._page)
        for path in _PAGES:
            if path != "/":
                app.router.add_get(path, self._page)
        app.router.add_get("/ws", self._socket)
        app.router.add_get("/status", self._status)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port, reuse_address=False)
        await site.start()
        self.port = site._server.sockets[0].getsockname()[1]
        self.renderer.start()
        return self.port

    async def close(self) -> None:
        for v in list(self.viewers):
            await v.ws.close()
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    # -- request checks -------------------------------------------------------------------
    def _host_ok(self, request) -> bool:
        name, port = _split_host(request.headers.get("Host", ""))
        if port is not None and port != self.port:
            return False
        if port is None and self.port != 80:
            return False
        if _is_loopback(name):
            return True
        if not self.allow_remote:
            return False
        try:                       # an IP literal: no name for an attacker's DNS to rebind
            ipaddress.ip_address(name)
            return True
        except ValueError:
            return name == self.host.lower()

    def _token_ok(self, request) -> bool:
        if self.token is None:
            return True
        given = request.query.get("token", "")
        return hmac.compare_digest(given.encode(), self.token.encode())

    async def _guard_impl(self, request, handler):
        from aiohttp import web
        if request.method != "GET":
            return web.Response(status=405, text="foveated-mi live view: GET only\n")
        if not self._host_ok(request):
            return web.Response(status=403, text="foveated-mi live view: refused: the Host "
                                "header does not name this server\n")
        response = await handler(request)
        if isinstance(response, web.Response):
            response.headers.setdefault("X-Content-Type-Options", "nosniff")
            response.headers.setdefault("Referrer-Policy", "no-referrer")
            response.headers.setdefault("Cache-Control", "no-store")
        return response

    @property
    def _guard(self):
        from aiohttp import web

        @web.middleware
        async def guard(request, handler):
            return await self._guard_impl(request, handler)
        return guard

    # -- pages ----------------------------------------------------------------------------
    async def _page(self, request):
        from aiohttp import web
        name = _PAGES[request.path]
        if name == "index.html" and not self._token_ok(request):
            return web.Response(status=403, text="foveated-mi live view: refused: open the "
                                "address printed with its token\n")
        with open(os.path.join(STATIC, name), "rb") as f:
            body = f.read()
        headers = {}
        if name == "index.html":
            headers["Content-Security-Policy"] = (
                "default-src 'self'; img-src 'self' blob: data:; connect-src 'self'; "
                "script-src 'self'; style-src 'self'; object-src 'none'; base-uri 'none'; "
                "form-action 'none'")
        return web.Response(body=body, headers=headers,
                            content_type=_CONTENT_TYPES[os.path.splitext(name)[1]],
                            charset="utf-8")

    async def _status(self, request):
        from aiohttp import web
        if not self._token_ok(request):
            return web.Response(status=403, text="foveated-mi live view: refused\n")
        r = self.renderer
        return web.json_response({"frames_rendered": r.frames_rendered, "viewers":
                                  len(self.viewers), "active": r.active, "resting": r.resting,
                                  "dropped": r.dropped, "last_error": r.last_error})

    # -- the socket -----------------------------------------------------------------------
    def _origin_ok(self, request) -> bool:
        origin = request.headers.get("Origin")
        if origin is None:          # not a browser (a browser always sends one here)
            return True
        from urllib.parse import urlsplit
        try:
            o = urlsplit(origin)
        except ValueError:
            return False
        return o.scheme in ("http", "https") and o.netloc.lower() == \
            request.headers.get("Host", "").strip().lower()

    async def _socket(self, request):
        from aiohttp import web, WSMsgType
        if not self._origin_ok(request):
            return web.Response(status=403, text="foveated-mi live view: refused: a page "
                                "from another origin\n")
        if not self._token_ok(request):
            return web.Response(status=403, text="foveated-mi live view: refused: wrong or "
                                "missing token\n")
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=protocol.MAX_MESSAGE_BYTES)
        await ws.prepare(request)
        if len(self.viewers) >= self.max_viewers:
            self.refused += 1
            await ws.send_str(json.dumps({"type": "refused", "message":
                                          f"foveated-mi: refused: {self.max_viewers} pages "
                                          "already share this renderer; close one and reload"}))
            await ws.close()
            return ws
        viewer = _Viewer(ws)
        self.viewers.append(viewer)
        self.renderer.set_active(True)
        sender = asyncio.ensure_future(self._sender(viewer))
        try:
            await ws.send_str(json.dumps(self._state()))
            if self._latest is not None:
                viewer.wake.set()
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    await self._handle(viewer, msg.data)
                elif msg.type == WSMsgType.BINARY:
                    await self._reply_error(viewer, ParameterError(
                        "message", "<binary>", "a JSON text message"))
                else:
                    break
        finally:
            sender.cancel()
            if viewer in self.viewers:
                self.viewers.remove(viewer)
            if not self.viewers:
                self.renderer.set_active(False)
        return ws

    def _state(self) -> dict:
        s = self.renderer.state()
        s["viewers"] = len(self.viewers)
        return s

    async def _broadcast(self, obj: dict) -> None:
        text = json.dumps(obj)
        for v in list(self.viewers):
            try:
                await v.ws.send_str(text)
            except (ConnectionError, RuntimeError):
                pass

    async def _reply_error(self, viewer: _Viewer, e: ParameterError) -> None:
        await viewer.ws.send_str(json.dumps({"type": "error",
                                             "message": protocol.error_text(e)}))

    async def _handle(self, viewer: _Viewer, data: str) -> None:
        r = self.renderer
        try:
            kind, m = protocol.parse(data)
            if kind == "ack":
                viewer.unacked = [k for k in viewer.unacked if k > m["frame"]]
                viewer.wake.set()
                r.wake()
                return
            if kind == "gaze":
                r.set_gaze(m["x"], m["y"], m["seq"])
                return
            if kind == "move":
                r.move(**m)
                return
            if kind == "home":
                r.home()
            elif kind == "lock":
                r.set_lock(m["on"])
            elif kind == "settings":
                r.change_settings(m)
            elif kind == "view":
                r.set_view(**m)
            elif kind == "gaze_source":
                r.set_gaze_source(m["source"], m.get("csv"), m.get("name", "gaze.csv"))
            elif kind == "record":
                result = await asyncio.get_running_loop().run_in_executor(None, r.record,
                                                                          m["on"])
                if result is not None:
                    await viewer.ws.send_str(json.dumps({"type": "recording", **result}))
        except ParameterError as e:
            await self._reply_error(viewer, e)
            return
        await self._broadcast(self._state())

    # -- frames ---------------------------------------------------------------------------
    def _saturated(self) -> bool:
        """Every page has ``max_inflight`` frames unacknowledged (render thread asks)."""
        viewers = list(self.viewers)
        if not viewers:
            return False
        now = time.monotonic()
        for v in viewers:
            if v.unacked and now - v.sent_at > 2.0:     # a page that stopped answering
                v.unacked.clear()
        return all(len(v.unacked) >= self.max_inflight for v in viewers)

    def _publish_threadsafe(self, frame) -> None:
        loop = self.loop
        if loop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(self._publish, frame)
            except RuntimeError:    # the loop closed meanwhile
                pass

    def _publish(self, frame) -> None:
        if not self._latest_sent:
            self.renderer.dropped += 1
        self._latest = frame
        self._latest_sent = False
        for v in self.viewers:
            v.wake.set()
        if "rebuild" in frame.meta:        # the settings now rendered
            asyncio.ensure_future(self._broadcast(self._state()))

    def _error_threadsafe(self, text: str) -> None:
        loop = self.loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(
                lambda: asyncio.ensure_future(self._broadcast({"type": "error",
                                                               "message": text})))

    async def _sender(self, viewer: _Viewer) -> None:
        try:
            while not viewer.ws.closed:
                await viewer.wake.wait()
                viewer.wake.clear()
                frame = self._latest
                if frame is None or frame.index <= viewer.last_sent:
                    continue
                if len(viewer.unacked) >= self.max_inflight:
                    continue            # an ack wakes us again
                await viewer.ws.send_bytes(frame.packet)
                viewer.last_sent = frame.index
                viewer.unacked.append(frame.index)
                viewer.sent_at = time.monotonic()
                self._latest_sent = True
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass


class LiveView:
    """The live view in a background thread, for a notebook or a script.

    ``scene`` is a built-in name or an XML path (loaded here, in the calling thread, so a
    scene that fails raises before anything is served) or a loaded ``mi.Scene``.
    ``options`` are foveated options (``preset``, ``ray_budget``, ``denoiser``, ...). With
    ``token=True`` (the default) a random token guards the page. Display it in Jupyter with
    ``view`` as a cell's value (an IFrame) and end it with :meth:`stop`::

        view = LiveView("voxel-city", size=(480, 270), options={"preset": "vr"})
        view          # the page, embedded
        with view.paused():          # other Dr.Jit work while the page stays open
            img = mi.render(other_scene)
        view.stop()   # the server and the render loop end
    """

    def __init__(self, scene: Any = "cornell-box", *, size: tuple[int, int] | None = None,
                 spp: int = 1, options: dict | None = None, host: str = "127.0.0.1",
                 port: int = 0, token: bool | str = True, allow_remote: bool = False,
                 scene_params: dict | None = None, integrator: dict | None = None,
                 record_dir: str = os.path.join("out", "live"), gaze_csv: str | None = None,
                 jpeg_quality: int = 85, idle_frames: int | None = None,
                 max_fps: float | None = None, scene_name: str | None = None):
        import importlib.util
        from ..validate import check_int
        from .renderer import IDLE_FRAMES, MAX_FPS, LiveRenderer
        if importlib.util.find_spec("aiohttp") is None:
            raise ImportError("the live view needs aiohttp: pip install -e '.[view]' "
                              "(from a clone)")
        warning = check_bind(host, allow_remote)
        port = check_int("--port", port, 0, 65535)
        if size is not None:
            size = (check_int("--size W", size[0], 1, 16384),
                    check_int("--size H", size[1], 1, 16384))
        if warning is not None:
            sys.stderr.write(warning + "\n")
            token = token or True
        if token is True:
            token = secrets.token_urlsafe(16)
        self.token = token or None
        ref = scene_name
        if isinstance(scene, (str, os.PathLike)):
            ref = _scene_ref(scene)
            scene = _load(scene, size, spp, integrator, scene_params or {})
        self.renderer = LiveRenderer(scene, scene_ref=ref, scene_params=scene_params,
                                     integrator=integrator, spp=spp, options=options,
                                     record_dir=record_dir, gaze_csv=gaze_csv,
                                     jpeg_quality=jpeg_quality,
                                     idle_frames=idle_frames or IDLE_FRAMES,
                                     max_fps=MAX_FPS if max_fps is None else max_fps)
        self.server = LiveServer(self.renderer, host=host, port=port, token=self.token,
                                 allow_remote=allow_remote)
        self._ready = threading.Event()
        self._done = threading.Event()
        self._error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop_future = None
        self._thread = threading.Thread(target=self._serve, name="foveated-mi live server",
                                        daemon=True)
        self._thread.start()
        self._ready.wait(60)
        if self._error is not None:
            self.renderer.stop()
            raise self._error
        if not self._ready.is_set():
            raise RuntimeError("the live view's server did not start within 60 s")
        import atexit
        import weakref
        ref = weakref.ref(self)
        atexit.register(lambda: ref() is not None and ref().stop(5.0))

    def _serve(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._main())
        except BaseException as e:           # bind failure: raised in the caller's thread
            self._error = e
            self._ready.set()
        finally:
            try:
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()
                self._done.set()

    async def _main(self) -> None:
        self._stop_future = asyncio.get_running_loop().create_future()
        await self.server.start()
        self._ready.set()
        try:
            await self._stop_future
        finally:
            await self.server.close()

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def url(self) -> str:
        host = self.server.host
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    @property
    def running(self) -> bool:
        return not self._done.is_set()

    def stop(self, timeout: float = 30.0) -> None:
        """Stop the server and the render loop (idempotent); returns when both ended."""
        loop, fut = self._loop, self._stop_future
        if loop is not None and fut is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(lambda: fut.done() or fut.set_result(None))
            except RuntimeError:
                pass
        self._done.wait(timeout)
        self.renderer.stop(timeout)
        self._thread.join(timeout)

    def paused(self):
        """A block in which the live view renders nothing, for other Dr.Jit work in the same
        process (a notebook's renders): ``with view.paused(): img = mi.render(...)``."""
        return self.renderer.paused()

    def wait(self) -> None:
        """Block until :meth:`stop` (or Ctrl-C in the calling thread)."""
        while not self._done.wait(0.25):
            pass

    def iframe(self, width: int | str = "100%", height: int = 640):
        from IPython.display import IFrame
        return IFrame(self.url, width=width, height=height)

    def _repr_html_(self) -> str:
        return self.iframe()._repr_html_()

    def __repr__(self) -> str:
        return f"LiveView({self.url}, {'running' if self.running else 'stopped'})"

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


def _scene_ref(scene) -> str:
    from ..scenes import SCENES
    s = os.fspath(scene)
    return s if s in SCENES else os.path.abspath(s)


def _load(scene, size, spp, integrator, scene_params):
    """Load a scene; Mitsuba's own failure becomes the command line's one line."""
    from ..scenes import load_scene
    w, h = size if size is not None else (None, None)
    try:
        return load_scene(scene, width=w, height=h, spp=spp, integrator=integrator,
                          **scene_params)
    except ParameterError:
        raise
    except (RuntimeError, ValueError, OSError) as e:
        first = (str(e).strip().splitlines() or [type(e).__name__])[-1][:200]
        raise ParameterError("scene", os.fspath(scene),
                             f"a scene Mitsuba can load ({first})") from None
