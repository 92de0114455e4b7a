"""What the live view shows: 8-bit display images, overlays, and the frame packet.

:func:`display_u8` is :func:`foveated_mi.render.to_display` (Reinhard ``x / (1 + x)`` after
``2^exposure``, then the sRGB encoding) through a 4096-entry table, within one 8-bit level of
``round(255 * to_display(x))`` and about five times faster: a frame's conversion must cost
little next to its render.

Overlays are drawn into the 8-bit image before it is encoded: a heat map (the sampling
probability, the history count) and tints (the pixels traced this frame; a foveated
buffer's cells as a checkerboard). The page draws the eccentricity rings itself, from the
frame's gaze and the camera's field of view.

A frame travels as one binary WebSocket message (:func:`packet`): a 4-byte big-endian length
``n``, ``n`` bytes of UTF-8 JSON (the frame's numbers), then the JPEG.
"""
from __future__ import annotations

import functools
import io
import json
import struct

import numpy as np

__all__ = ["display_u8", "encode_jpeg", "packet", "unpack", "heat", "tint", "mark",
           "upscale"]

_LUT_LEVELS = 4096


@functools.lru_cache(maxsize=1)
def _srgb_table() -> np.ndarray:
    """8-bit sRGB code of each of the table's levels of ``y = x / (1 + x)`` in [0, 1]."""
    import colour
    y = np.arange(_LUT_LEVELS, dtype=np.float64) / (_LUT_LEVELS - 1)
    s = np.clip(colour.cctf_encoding(y, function="sRGB"), 0.0, 1.0)
    return np.round(s * 255.0).astype(np.uint8)


def display_u8(linear: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear radiance (H, W, 3) -> display-referred 8-bit sRGB (H, W, 3), as
    ``round(255 * to_display(linear, exposure))`` within one level. NaN -> 0."""
    x = np.asarray(linear, dtype=np.float32)[..., :3]
    x = np.nan_to_num(x, nan=0.0, posinf=1e30, neginf=0.0)
    if exposure:
        x = x * np.float32(2.0 ** exposure)
    np.maximum(x, 0.0, out=x)
    y = x / (1.0 + x)
    idx = (y * np.float32(_LUT_LEVELS - 1) + np.float32(0.5)).astype(np.uint16)
    return np.take(_srgb_table(), idx)


def encode_jpeg(rgb: np.ndarray, quality: int = 85) -> bytes:
    """JPEG bytes of an 8-bit (H, W, 3) image (Pillow; 4:2:0 chroma)."""
    from PIL import Image
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb)).save(buf, "JPEG", quality=int(quality))
    return buf.getvalue()


def packet(meta: dict, jpeg: bytes) -> bytes:
    """One frame as one binary message: length of the JSON, the JSON, the JPEG."""
    head = json.dumps(meta, separators=(",", ":"), allow_nan=False).encode()
    return struct.pack(">I", len(head)) + head + jpeg


def unpack(data: bytes) -> tuple[dict, bytes]:
    """Inverse of :func:`packet`: ``(meta, jpeg)``."""
    (n,) = struct.unpack(">I", data[:4])
    return json.loads(data[4:4 + n].decode()), data[4 + n:]


@functools.lru_cache(maxsize=2)
def _colormap(name: str) -> np.ndarray:
    """256 x 3 uint8 colours of a matplotlib colour map."""
    import matplotlib
    return (matplotlib.colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3] * 255).astype(np.uint8)


def _blend(img: np.ndarray, mask: np.ndarray, colour: np.ndarray, alpha: float) -> None:
    """In place: ``img[mask] = (1 - alpha) img + alpha colour`` (colour per pixel or one)."""
    if not mask.any():
        return
    src = img[mask].astype(np.float32)
    col = colour if np.ndim(colour) == 1 else colour[mask]
    img[mask] = np.clip((1.0 - alpha) * src + alpha * np.asarray(col, np.float32) + 0.5,
                        0, 255).astype(np.uint8)


def heat(img: np.ndarray, values: np.ndarray, valid: np.ndarray | None = None,
         alpha: float = 0.55, cmap: str = "viridis") -> None:
    """In place: blend a colour map of ``values`` (H, W) in [0, 1] where ``valid``."""
    v = np.nan_to_num(np.clip(values, 0.0, 1.0), nan=0.0)
    colours = _colormap(cmap)[(v * 255.0 + 0.5).astype(np.int32)]
    mask = np.ones(v.shape, bool) if valid is None else np.asarray(valid, bool)
    _blend(img, mask, colours, alpha)


def tint(img: np.ndarray, mask: np.ndarray, colour=(40, 255, 90), alpha: float = 0.6) -> None:
    """In place: tint the pixels of ``mask`` (H, W) with ``colour``."""
    _blend(img, np.asarray(mask, bool), np.asarray(colour, np.float32), alpha)


def mark(img: np.ndarray, mask: np.ndarray, colour=(255, 255, 255), alpha: float = 0.7) -> None:
    """In place: lighten or darken the pixels of ``mask`` towards ``colour``."""
    _blend(img, np.asarray(mask, bool), np.asarray(colour, np.float32), alpha)


def upscale(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear resize of an 8-bit image to ``width`` x ``height`` (Pillow)."""
    if img.shape[1] == width and img.shape[0] == height:
        return img
    from PIL import Image
    return np.asarray(Image.fromarray(img).resize((width, height), Image.BILINEAR))
