"""Image-quality metrics: PSNR and SSIM through scikit-image.

Both take a reference and a test image of the same shape, (H, W) or (H, W, C), and
compare all channels (``channel_axis=-1`` for 3-D arrays).

``data_range`` (the ``L`` of PSNR's ``10 log10(L^2 / MSE)`` and of SSIM's constants
``(K1 L)^2``, ``(K2 L)^2``), when None:

* ``1.0`` when every reference value lies in [0, 1]: the display-referred images
  (tone-mapped, or PNG / 255) the metrics are meant for; this matches scikit-image's own
  default for such float images;
* otherwise ``max(reference) - min(reference)`` (an HDR reference); pass ``data_range``
  explicitly to compare HDR images on a fixed scale. A constant HDR reference has no range
  and needs an explicit value.

Both images must be finite: a NaN or inf raises ParameterError naming the image, instead of
turning the metric into NaN.

SSIM uses scikit-image's defaults (uniform 7x7 window, K1 = 0.01, K2 = 0.03, sample
covariance). An image smaller than 7 px on a side uses the largest odd window
``<= min(H, W)``; below 3 px no window fits and SSIM is ``nan``.
"""
from __future__ import annotations

import math

import numpy as np

from .validate import ParameterError, check_range

SSIM_WIN_SIZE = 7


def _check_pair(reference, test) -> tuple[np.ndarray, np.ndarray]:
    ref = np.asarray(reference)
    tst = np.asarray(test)
    for name, arr in (("reference", ref), ("test", tst)):
        if arr.ndim not in (2, 3) or 0 in arr.shape or not (
                np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise ParameterError(name, f"{arr.dtype} array of shape {arr.shape}",
                                 "a non-empty real (H, W) or (H, W, C) array")
    if ref.shape != tst.shape:
        raise ParameterError("test", f"array of shape {tst.shape}",
                             f"the reference's shape {ref.shape}")
    ref = ref.astype(np.float64)
    tst = tst.astype(np.float64)
    for name, arr in (("reference", ref), ("test", tst)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        if bad:
            raise ParameterError(name, f"array with {bad} NaN/inf values", "finite values")
    return ref, tst


def _data_range(ref: np.ndarray, data_range) -> float:
    if data_range is not None:
        return check_range("data_range", data_range, lo=0.0, lo_open=True)
    lo, hi = float(ref.min()), float(ref.max())
    if lo >= 0.0 and hi <= 1.0:
        return 1.0
    if hi > lo:
        return hi - lo
    raise ParameterError("data_range", None, "a number > 0 for a constant reference "
                         "outside [0, 1]")


def psnr(reference, test, data_range: float | None = None) -> float:
    """Peak signal-to-noise ratio in dB, ``10 log10(L^2 / MSE)`` over all pixels and channels
    (``skimage.metrics.peak_signal_noise_ratio``); ``inf`` for identical images.
    """
    from skimage.metrics import peak_signal_noise_ratio

    ref, tst = _check_pair(reference, test)
    rng = _data_range(ref, data_range)
    if np.array_equal(ref, tst):
        return math.inf                      # skimage divides by MSE = 0 with a warning
    return float(peak_signal_noise_ratio(ref, tst, data_range=rng))


def ssim_win_size(height: int, width: int) -> int | None:
    """SSIM window side: 7, or the largest odd number <= min(H, W); None below 3 px."""
    side = min(height, width, SSIM_WIN_SIZE)
    if side % 2 == 0:
        side -= 1
    return side if side >= 3 else None


def ssim(reference, test, data_range: float | None = None) -> float:
    """Mean structural similarity (Wang et al. 2004) through
    ``skimage.metrics.structural_similarity``, averaged over channels; ``nan`` when the image
    is smaller than 3 px on a side (see the module docstring)."""
    from skimage.metrics import structural_similarity

    ref, tst = _check_pair(reference, test)
    rng = _data_range(ref, data_range)
    win = ssim_win_size(ref.shape[0], ref.shape[1])
    if win is None:
        return math.nan
    return float(structural_similarity(ref, tst, data_range=rng, win_size=win,
                                       channel_axis=-1 if ref.ndim == 3 else None))


def compare(reference, test, data_range: float | None = None) -> dict[str, float]:
    """``{"psnr": psnr(...), "ssim": ssim(...)}`` with the same ``data_range``."""
    return {"psnr": psnr(reference, test, data_range),
            "ssim": ssim(reference, test, data_range)}
