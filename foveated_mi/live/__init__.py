"""The live view: a browser page that shows foveated frames as they are rendered.

``foveated-mi view SCENE`` (or :class:`LiveView` in a notebook) loads a scene, starts a small
web server on 127.0.0.1 and a render thread, and serves a page (static HTML and JavaScript,
no build step) that shows each frame with its frame time and ray fraction. The mouse over
the image is the gaze; keys and a drag move and turn the camera; overlays, a split view,
the preset and the ray budget are controls of the page. Modules:

- :mod:`.renderer`: the render loop (:class:`~.renderer.LiveRenderer`): inputs in, frames
  out, latest-frame-wins; no web code; it holds the three jobs below;
- :mod:`.inputs`: the gaze, the flying camera, the gaze sources and the mailbox of inputs;
- :mod:`.recording`: a recorded walk-through's poses and its sequence config;
- :mod:`.panels`: the overlays and the split view's panels;
- :mod:`.server`: the aiohttp server (one WebSocket per page, Origin/Host/token checks) and
  :class:`LiveView`, which runs it in a background thread;
- :mod:`.protocol`: the fixed set of messages a page may send, each validated;
- :mod:`.display`: display conversion, overlays and the frame packet;
- :mod:`.poses`: per-frame poses (CSV), which the page records and ``foveated-mi sequence``
  replays (:mod:`foveated_mi.poses`, by its other name);
- :mod:`.client`: a plain Python client of the page's socket (rates without a browser).

The web stack (aiohttp) is the optional extra ``view``: ``pip install -e '.[view]'``.
"""
from __future__ import annotations

__all__ = ["LiveView", "LiveRenderer", "PoseTrack", "Pose"]


def __getattr__(name):   # lazy: importing the package needs neither aiohttp nor Mitsuba
    if name == "LiveView":
        from .server import LiveView
        return LiveView
    if name == "LiveRenderer":
        from .renderer import LiveRenderer
        return LiveRenderer
    if name in ("PoseTrack", "Pose"):
        from . import poses
        return getattr(poses, name)
    raise AttributeError(name)
