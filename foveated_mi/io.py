"""Image files: multi-layer OpenEXR, 8-bit sRGB PNG, and atomic writes.

EXR layout
    One single-part scanline EXR (ZIP compression, lossless). A layer is a group of
    channels named ``<layer>.<channel>``, the OpenEXR naming convention for layers that
    Nuke, Blender and tev read. The channel names depend on the layer's channel count C:

    ====  =====================
    C     channels
    ====  =====================
    1     ``Y``
    2     ``X``, ``Y``  (a 2-D vector, e.g. previous-pixel coordinates)
    3     ``R``, ``G``, ``B``
    4     ``R``, ``G``, ``B``, ``A``
    ====  =====================

    The layer name ``""`` writes unprefixed channels (``R``, ``G``, ``B``): the image most
    viewers show first. Pixel types are kept: float32 -> FLOAT, float16 -> HALF,
    uint32 -> UINT (site indices); float64 is stored as float32, bool/uint8/uint16 as uint32.
    :func:`read_exr` reads any single- or multi-part scanline/tiled file back into the same
    ``{layer: (H, W, C) array}`` dictionary, so ``read_exr(write_exr(...))`` is exact.

Atomic writes
    Every writer goes through :func:`atomic_write`: the data is written to a temporary file
    in the target's directory, flushed to disk and moved over the target with ``os.replace``
    (atomic on POSIX), so an interrupted or failed write never replaces a good file.

Errors are one line: :class:`~foveated_mi.validate.ParameterError` for bad arrays or
arguments, ``OSError`` (with the path) for file-system problems.
"""
from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from collections.abc import Mapping
from typing import Any, Iterator

import numpy as np

from .validate import ParameterError

#: Channel names written for a layer of C channels.
CHANNEL_NAMES = {1: ("Y",), 2: ("X", "Y"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}

# Order used when reading channel sets that are not one of CHANNEL_NAMES.
_CHANNEL_ORDER = ("R", "G", "B", "A", "X", "Y", "Z", "W", "U", "V")

# Header attributes that describe the pixel layout: set by write_exr, never by attrs.
RESERVED_ATTRS = frozenset({
    "channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
    "screenWindowCenter", "screenWindowWidth", "type", "name", "tiles", "version",
    "chunkCount", "maxSamplesPerPixel"})


# ------------------------------------------------------------------------------------------
# Atomic writes
# ------------------------------------------------------------------------------------------

def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str | None = None,
                 **open_kwargs: Any) -> Iterator[Any]:
    """Write ``path`` all at once, or not at all: a block that raises leaves ``path`` as it was.

    Parameters
    ----------
    path : str or os.PathLike
        Target: flushed, given ``open``'s permissions (or the old file's), renamed over at the end.
    mode, **open_kwargs : optional
        None, or a writing mode such as ``"w"`` or ``"wb"`` with the other arguments of ``open``.

    Yields
    ------
    tmp : str or file object
        A temporary file beside ``path``, with its extension: its path (``mode`` None, for
        writers that take a file name) or the file open in ``mode``.
    """
    path = os.fspath(path)
    if mode is not None and (not isinstance(mode, str) or "w" not in mode):
        raise ParameterError("mode", mode, "None or a writing mode such as 'w' or 'wb'")
    target = os.path.abspath(path)
    directory = os.path.dirname(target)
    if not os.path.isdir(directory):
        raise FileNotFoundError(errno.ENOENT, f"cannot write {path}: directory {directory} "
                                "does not exist", path)
    if os.path.isdir(target):
        raise IsADirectoryError(errno.EISDIR, f"cannot write {path}: it is a directory", path)
    base = os.path.basename(target)
    stem, ext = os.path.splitext(base)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{stem}.tmp-", suffix=ext, dir=directory)
    except OSError as e:
        raise type(e)(e.errno, f"cannot write {path}: {e.strerror}", path) from None
    fd_owned = True   # until closed or handed to a file object (never close it twice)
    try:
        if mode is None:
            os.close(fd)
            fd_owned = False
            yield tmp
        else:
            f = os.fdopen(fd, mode, **open_kwargs)
            fd_owned = False
            with f:
                yield f
                f.flush()
        with open(tmp, "rb") as f:          # flush the data before the rename makes it visible
            os.fsync(f.fileno())
        try:
            perm = os.stat(target).st_mode & 0o7777
        except FileNotFoundError:
            perm = 0o666 & ~_umask()
        os.chmod(tmp, perm)
        os.replace(tmp, target)
    except BaseException:
        if fd_owned:
            with contextlib.suppress(OSError):
                os.close(fd)
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
        raise


# ------------------------------------------------------------------------------------------
# OpenEXR
# ------------------------------------------------------------------------------------------

def _layer_array(name: str, value: Any) -> np.ndarray:
    """A layer as an (H, W, C) array of float16, float32 or uint32."""
    label = f"layers[{name!r}]"
    arr = np.asarray(value)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3 or arr.shape[2] not in CHANNEL_NAMES or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ParameterError(label, f"array of shape {arr.shape}",
                             "an (H, W) or (H, W, C) array with H, W >= 1 and C in 1..4")
    if arr.dtype in (np.float32, np.float16, np.uint32):
        return arr
    if arr.dtype == np.float64:
        return arr.astype(np.float32)
    if arr.dtype in (np.bool_, np.uint8, np.uint16):
        return arr.astype(np.uint32)
    raise ParameterError(label, f"array of dtype {arr.dtype}",
                         "float16, float32, float64, uint32, uint16, uint8 or bool pixels")


def _attr_value(key: Any, value: Any) -> Any:
    """A header attribute value OpenEXR stores faithfully (checked: it silently wraps
    ints above 2^31 and stores bools as ints)."""
    label = f"attrs[{key!r}]"
    allowed = ("a str, an int32, a float, a list of str, 2 or 3 numbers, "
               "or a 3x3/4x4 float matrix")
    if not isinstance(key, str) or not key or key in RESERVED_ATTRS:
        raise ParameterError("attrs key", key, "a non-empty str other than "
                             + ", ".join(sorted(RESERVED_ATTRS)))
    if isinstance(value, (bool, np.bool_)):
        raise ParameterError(label, value, allowed)
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        if not -2**31 <= int(value) < 2**31:
            raise ParameterError(label, value, allowed)
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, str) for v in value):
        return list(value)
    if isinstance(value, (list, tuple)) and len(value) in (2, 3) and all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            for v in value):
        return tuple(float(v) for v in value)
    if isinstance(value, np.ndarray) and value.shape in ((3, 3), (4, 4)) \
            and value.dtype in (np.float32, np.float64):
        return value
    raise ParameterError(label, value, allowed)


def write_exr(path: str | os.PathLike, layers: Mapping[str, np.ndarray], *,
              attrs: Mapping[str, Any] | None = None) -> None:
    """Write named layers to one multi-layer OpenEXR file (layout in the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        Target file; written atomically (see :func:`atomic_write`).
    layers : mapping of str to numpy.ndarray
        ``{name: array}``; arrays (H, W) or (H, W, C), C in 1..4, all the same H, W.
    attrs : mapping or None, optional
        Extra header attributes (str, int32, float, list of str, 2 or 3 numbers, 3x3/4x4 float
        matrices), e.g. render settings; layout keys are reserved.

    Raises
    ------
    ParameterError
        For bad layers or attributes.
    OSError
        When the file cannot be written.
    """
    import OpenEXR

    if not isinstance(layers, Mapping) or not layers:
        raise ParameterError("layers", type(layers).__name__,
                             "a non-empty dict {name: (H, W, C) array}")
    channels: dict[str, np.ndarray] = {}
    shape = None
    for name, value in layers.items():
        if not isinstance(name, str):
            raise ParameterError("layer name", name, "a str")
        arr = _layer_array(name, value)
        if shape is None:
            shape = arr.shape[:2]
        elif arr.shape[:2] != shape:
            raise ParameterError(f"layers[{name!r}]", f"array of shape {arr.shape}",
                                 f"the same (H, W) = {shape} as the other layers")
        prefix = f"{name}." if name else ""
        for k, ch in enumerate(CHANNEL_NAMES[arr.shape[2]]):
            # OpenEXR reads the buffer as C-contiguous (checked: a strided view is garbled).
            channels[prefix + ch] = np.ascontiguousarray(arr[:, :, k])

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if attrs is not None:
        if not isinstance(attrs, Mapping):
            raise ParameterError("attrs", type(attrs).__name__, "a dict or None")
        for key, value in attrs.items():
            header[key] = _attr_value(key, value)

    with atomic_write(path) as tmp:
        try:
            OpenEXR.File(header, channels).write(tmp)
        except RuntimeError as e:
            raise OSError(f"cannot write {os.fspath(path)}: {e}") from None


def _split_channel(full: str) -> tuple[str, str]:
    layer, dot, ch = full.rpartition(".")
    return (layer, ch) if dot else ("", full)


def _order(names: list[str]) -> list[str]:
    for expected in CHANNEL_NAMES.values():
        if set(names) == set(expected):
            return list(expected)
    rank = {c: i for i, c in enumerate(_CHANNEL_ORDER)}
    return sorted(names, key=lambda c: (rank.get(c, len(rank)), c))


def _open_exr(path: str | os.PathLike, header_only: bool = False):
    import OpenEXR

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(errno.ENOENT, f"cannot read {path}: no such file", path)
    try:
        return OpenEXR.File(path, separate_channels=True, header_only=header_only)
    except RuntimeError as e:
        raise OSError(f"cannot read {path}: not a readable OpenEXR file ({e})") from None


def read_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read an OpenEXR file into ``{layer: (H, W, C) array}`` (inverse of :func:`write_exr`).

    Channels ``<layer>.<name>`` are grouped by layer (the text before the last dot; unprefixed
    channels form layer ``""``) and ordered as in :data:`CHANNEL_NAMES`, other sets in the order
    R, G, B, A, X, Y, Z, W, U, V, then alphabetically. Pixel types are kept. Channels of all
    parts of a multi-part file are merged.

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    layers : dict of str to numpy.ndarray
        One (H, W, C) array per layer.

    Raises
    ------
    OSError
        For a missing or unreadable file, or a layer that mixes shapes or pixel types.
    """
    f = _open_exr(path)
    groups: dict[str, dict[str, np.ndarray]] = {}
    for part in f.parts:
        for full, channel in part.channels.items():
            layer, ch = _split_channel(full)
            if ch in groups.setdefault(layer, {}):
                raise OSError(f"cannot read {os.fspath(path)}: channel {full!r} appears in "
                              "more than one part")
            groups[layer][ch] = channel.pixels
    out = {}
    for layer, chans in groups.items():
        names = _order(list(chans))
        shapes = {chans[c].shape for c in names}
        dtypes = {chans[c].dtype for c in names}
        if len(shapes) != 1 or len(dtypes) != 1:
            raise OSError(f"cannot read {os.fspath(path)}: layer {layer!r} mixes pixel shapes "
                          f"{sorted(shapes)} or types {sorted(map(str, dtypes))}")
        out[layer] = np.stack([chans[c] for c in names], axis=-1)
    return out


def read_exr_attrs(path: str | os.PathLike) -> dict[str, Any]:
    """The header attributes of an OpenEXR file other than the layout keys.

    Parameters
    ----------
    path : str or os.PathLike
        The file, as for :func:`read_exr` (only its header is read).

    Returns
    -------
    attrs : dict
        Attribute name to value, without :data:`RESERVED_ATTRS`.
    """
    f = _open_exr(path, header_only=True)
    return {k: v for k, v in f.header().items() if k not in RESERVED_ATTRS}


# ------------------------------------------------------------------------------------------
# PNG
# ------------------------------------------------------------------------------------------

def encode_srgb8(linear_rgb: np.ndarray, *, exposure: float = 0.0,
                 tonemap: str | None = None) -> np.ndarray:
    """Linear colour -> 8-bit sRGB, the pixels :func:`write_png` writes.

    ``v = linear * 2^exposure`` (``tonemap=None``), or ``v = tonemap(linear, tonemap,
    exposure)`` through :func:`foveated_mi.postprocess.tonemap`; then NaN -> 0 (+inf -> 1) and
    clip to [0, 1]; then the sRGB inverse EOTF of IEC 61966-2-1 (``colour.cctf_encoding(v,
    function="sRGB")``) and ``round(255 v)``. An alpha channel is clipped but neither exposed,
    tone-mapped nor sRGB-encoded.

    Parameters
    ----------
    linear_rgb : numpy.ndarray
        Real (H, W), (H, W, 1), (H, W, 3) or (H, W, 4).
    exposure : float, optional
        Exposure in stops.
    tonemap : str or None, optional
        A key of :data:`~foveated_mi.postprocess.tonemap.TONEMAPPERS`, or None.

    Returns
    -------
    pixels : numpy.ndarray
        uint8 (H, W, C), C = 1, 3 or 4.
    """
    import colour

    from .postprocess.tonemap import TONEMAPPERS, check_exposure
    from .validate import check_choice

    arr = np.asarray(linear_rgb)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3 or arr.shape[2] not in (1, 3, 4) or arr.shape[0] < 1 or arr.shape[1] < 1 \
            or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ParameterError("linear_rgb", f"{arr.dtype} array of shape {arr.shape}",
                             "a real (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) array")
    exposure = check_exposure(exposure)
    if tonemap is not None:
        check_choice("tonemap", tonemap, TONEMAPPERS)
    arr = arr.astype(np.float64)
    color, alpha = (arr[..., :3], arr[..., 3:]) if arr.shape[2] == 4 else (arr, None)

    if tonemap is None:
        color = color * 2.0 ** exposure
    else:
        color = _tonemap_numpy(color, tonemap, exposure)
    color = np.clip(np.nan_to_num(color, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    encoded = colour.cctf_encoding(color, function="sRGB")
    if alpha is not None:
        alpha = np.clip(np.nan_to_num(alpha, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
        encoded = np.concatenate([encoded, alpha], axis=-1)
    return np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)


def _tonemap_numpy(color: np.ndarray, operator: str, exposure: float) -> np.ndarray:
    """Apply the Dr.Jit tone mapper to an (H, W, 1|3) array (one definition of each curve)."""
    import drjit as dr
    import mitsuba as mi

    from .postprocess.tonemap import tonemap as tonemap_fn

    h, w, c = color.shape
    flat = np.ascontiguousarray(np.broadcast_to(color, (h, w, 3)).reshape(-1, 3).T,
                                dtype=np.float32)
    with dr.suspend_grad():
        out = tonemap_fn(mi.Color3f(flat), operator, exposure)
    out = np.asarray(out, dtype=np.float64).reshape(3, -1).T.reshape(h, w, 3)
    return out[..., :c]


def write_png(path: str | os.PathLike, linear_rgb: np.ndarray, *, exposure: float = 0.0,
              tonemap: str | None = None) -> None:
    """Write a linear image as an 8-bit sRGB PNG (encoding in :func:`encode_srgb8`), atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    linear_rgb : numpy.ndarray
        (H, W), (H, W, 1), (H, W, 3) or (H, W, 4).
    exposure : float, optional
        Exposure in stops.
    tonemap : str or None, optional
        Tone-mapping operator, or None.
    """
    import imageio.v3 as iio

    pixels = encode_srgb8(linear_rgb, exposure=exposure, tonemap=tonemap)
    if pixels.shape[2] == 1:
        pixels = pixels[:, :, 0]
    with atomic_write(path) as tmp:
        iio.imwrite(tmp, pixels, extension=".png")


def format_table(rows: list[tuple[str, ...]]) -> str:
    """Rows of strings as an aligned text table.

    Parameters
    ----------
    rows : list of tuple of str
        The first row is the header (underlined); all rows have its length.

    Returns
    -------
    table : str
        The lines, the first column left-aligned, the others right-aligned.
    """
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = []
    for j, r in enumerate(rows):
        lines.append("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in
                               enumerate(zip(r, widths))))
        if j == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)
