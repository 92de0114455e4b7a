r"""Image-quality metrics: PSNR, SSIM and FLIP over the full frame, the fovea and the periphery,
and an eccentricity-weighted PSNR.

Every metric takes a reference and a test image of the same shape, (H, W) or (H, W, C), and
compares all channels (``channel_axis=-1`` for 3-D arrays). The images the metrics are meant
for are display-referred, in [0, 1] (:func:`foveated_mi.render.to_display`: Reinhard, then
sRGB).

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

**Regions.** The fovea is the set of pixels whose centre lies closer to the gaze than θ, the
distance being measured as in the sampling pass (:func:`foveated_mi.frame.sampling.normalized_distance`):

.. math::

    d_i = \frac{\lVert (x_i + \tfrac12,\ y_i + \tfrac12) - (g_x W,\ g_y H) \rVert}
               {\tfrac12\sqrt{W^2 + H^2}},
    \qquad \text{fovea} = \{ i : d_i < \theta \},

with the gaze ``g`` in normalised film coordinates (origin top-left, x to the right, y down).
The periphery is its complement. A masked metric uses only the pixels where ``mask`` is True
(all channels); an empty mask gives ``nan`` (there is nothing to measure), never an error.

* masked PSNR: ``10 log10(L^2 / MSE_mask)``, MSE over the masked pixels and all channels;
* masked SSIM: the mean over the masked pixels of scikit-image's full SSIM map (averaged over
  channels). Unlike the unmasked SSIM, which is scikit-image's mean over the pixels whose
  window lies inside the image, it counts border pixels too (their windows are reflected at
  the border), so an all-True mask differs from the unmasked value by the border's share;
* masked FLIP: the mean over the masked pixels of the FLIP error map.

**Eccentricity weighting.** :func:`eccentricity_weights` follows the sampling law's falloff:
the weight of pixel ``i`` is proportional to the probability with which the foveated
integrator traces it, :math:`P(d_i) = 1/(w d_i^2 + 1)`, :math:`w = (1/\sigma_p - 1)/\theta^2`,
normalised to sum 1. :func:`eccentricity_weighted_psnr` is the PSNR of the weighted MSE
:math:`\sum_i \omega_i \tfrac1C \sum_c (r_{ic} - t_{ic})^2`.

**Temporal instability (flicker).** :func:`temporal_instability` scores a sequence against
a reference sequence of its own (one reference per frame, so a camera's own motion cancels):
the root mean square of :math:`(t_k - t_{k-1}) - (r_k - r_{k-1})` per ring of eccentricity
in degrees, over the periphery and over the whole frame. A still error is no flicker; noise
that changes from frame to frame is. :func:`temporal_instability_map` gives the same figure
per pixel, to see where a sequence flickers.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .validate import ParameterError, check_point2, check_range

__all__ = ["psnr", "ssim", "flip", "compare", "fovea_mask", "eccentricity_weights",
           "eccentricity_weighted_psnr", "normalized_distance", "ssim_win_size",
           "temporal_instability", "TemporalInstability", "flicker_ring_columns",
           "temporal_instability_map",
           "COMPARE_KEYS", "SSIM_WIN_SIZE", "FLICKER_RINGS_DEG", "FLICKER_KEYS"]

SSIM_WIN_SIZE = 7

#: Keys of :func:`compare`, always all present (``nan`` where not computable).
COMPARE_KEYS = ("psnr", "ssim", "flip", "psnr_fovea", "psnr_periphery", "ssim_fovea",
                "ssim_periphery", "flip_fovea", "flip_periphery", "psnr_eccentricity")


# ---------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------

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


def _check_mask(mask, shape: tuple[int, ...], name: str = "mask") -> np.ndarray | None:
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.dtype != np.bool_ or m.shape != tuple(shape[:2]):
        raise ParameterError(name, f"{m.dtype} array of shape {m.shape}",
                             f"a boolean array of shape {tuple(shape[:2])} (the images' H, W)")
    return m


def _check_shape(shape) -> tuple[int, int]:
    allowed = "an image shape (H, W) or (H, W, C) with H, W >= 1"
    try:
        dims = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        raise ParameterError("shape", shape, allowed) from None
    if len(dims) not in (2, 3) or min(dims[:2]) < 1 or any(
            isinstance(s, bool) or int(s) != s for s in shape):
        raise ParameterError("shape", shape, allowed)
    return dims[0], dims[1]


# ---------------------------------------------------------------------------------------------
# Regions and weights
# ---------------------------------------------------------------------------------------------

def normalized_distance(shape, gaze) -> np.ndarray:
    """Distance of each pixel centre to the gaze over half the film diagonal, in double precision.

    The NumPy twin of :func:`foveated_mi.frame.sampling.normalized_distance` (same convention;
    the tests compare the two).

    Parameters
    ----------
    shape : tuple of int
        Image shape, (H, W) or (H, W, C).
    gaze : tuple of float
        Normalised film coordinates (origin top-left); may lie off-screen.

    Returns
    -------
    distance : numpy.ndarray
        float64 (H, W).
    """
    h, w = _check_shape(shape)
    gx, gy = check_point2("gaze", gaze)
    half_diag = 0.5 * math.sqrt(w * w + h * h)
    dx = (np.arange(w, dtype=np.float64) + 0.5) - gx * w
    dy = (np.arange(h, dtype=np.float64) + 0.5) - gy * h
    return np.sqrt(dx[None, :] ** 2 + dy[:, None] ** 2) / half_diag


def fovea_mask(shape, gaze, theta) -> np.ndarray:
    """Boolean mask of the fovea: pixel centres with normalised distance ``d < theta`` to ``gaze``
    (see the module docstring).

    Parameters
    ----------
    shape : tuple of int
        Image shape, (H, W) or (H, W, C).
    gaze : tuple of float
        Normalised film coordinates; it may lie off-screen (the mask may then be empty).
    theta : float
        The fovea's radius θ, a finite number > 0 (a fraction of half the film diagonal).

    Returns
    -------
    mask : numpy.ndarray
        bool (H, W).
    """
    theta = check_range("theta", theta, 0.0, None, lo_open=True)
    return normalized_distance(shape, gaze) < theta


def eccentricity_weights(shape, gaze, theta, sigma_p) -> np.ndarray:
    r"""Weights following the sampling law's falloff, normalised to sum 1:

    .. math::

        \omega_i = \frac{P(d_i)}{\sum_j P(d_j)}, \qquad P(d) = \frac{1}{w d^2 + 1}
        = \frac{1/w}{d^2 + 1/w},

    with ``w`` from :func:`foveated_mi.frame.sampling.sampling_weight` (so ``P(θ) = σp``). They are
    computed as ``m / (d_i^2 + 1/w)`` (``m`` the smallest denominator) and normalised, which
    keeps the limits exact: ``σp = 1`` (w = 0) gives uniform weights; a ``w`` that overflows
    (θ → 0) gives ``1/d^2`` weights, or all the weight on a pixel centred on the gaze.

    Parameters
    ----------
    shape : tuple of int
        Image shape, (H, W) or (H, W, C).
    gaze : tuple of float
        Normalised film coordinates.
    theta, sigma_p : float
        The sampling law's fovea radius θ and peripheral probability σp.

    Returns
    -------
    weights : numpy.ndarray
        float64 (H, W), summing to 1.
    """
    from .frame.sampling import sampling_weight

    w = sampling_weight(theta, sigma_p)
    d2 = normalized_distance(shape, gaze) ** 2
    if w == 0.0:
        v = np.ones_like(d2)
    else:
        eps = 1.0 / w                               # 0 when w overflowed to inf
        den = d2 + eps
        m = float(den.min())
        v = (den == 0.0).astype(np.float64) if m == 0.0 else m / den
    return v / v.sum()


# ---------------------------------------------------------------------------------------------
# PSNR
# ---------------------------------------------------------------------------------------------

def _psnr_from_mse(mse: float, rng: float) -> float:
    if mse == 0.0:
        return math.inf
    return float(10.0 * np.log10(rng * rng / mse))


def psnr(reference, test, data_range: float | None = None, mask=None) -> float:
    """Peak signal-to-noise ratio in dB, ``10 log10(L^2 / MSE)`` over all channels of the pixels in
    ``mask``.

    Parameters
    ----------
    reference, test : array_like
        Finite real images of one shape, (H, W) or (H, W, C).
    data_range : float or None, optional
        ``L``; None: from the whole reference (see the module docstring), so region values
        share one scale.
    mask : numpy.ndarray or None, optional
        bool (H, W): the pixels to measure (None: all, through
        ``skimage.metrics.peak_signal_noise_ratio``).

    Returns
    -------
    psnr : float
        In dB; ``inf`` when they are identical, ``nan`` for an empty mask.
    """
    from skimage.metrics import peak_signal_noise_ratio

    ref, tst = _check_pair(reference, test)
    m = _check_mask(mask, ref.shape)
    rng = _data_range(ref, data_range)
    if m is not None:
        if not m.any():
            return math.nan
        diff = ref[m] - tst[m]
        return _psnr_from_mse(float(np.mean(diff * diff, dtype=np.float64)), rng)
    if np.array_equal(ref, tst):
        return math.inf                      # skimage divides by MSE = 0 with a warning
    return float(peak_signal_noise_ratio(ref, tst, data_range=rng))


def eccentricity_weighted_psnr(reference, test, weights, data_range: float = 1.0) -> float:
    """PSNR of the weighted MSE, ``10 log10(L^2 / sum_i w_i mean_c (r_ic - t_ic)^2)``.

    Parameters
    ----------
    reference, test : array_like
        Finite real images of one shape, (H, W) or (H, W, C).
    weights : array_like
        (H, W) finite non-negative numbers with a positive sum (normalised here to sum 1; see
        :func:`eccentricity_weights`).
    data_range : float, optional
        ``L``, > 0.

    Returns
    -------
    psnr : float
        In dB; ``inf`` when the weighted error is 0.
    """
    ref, tst = _check_pair(reference, test)
    rng = check_range("data_range", data_range, lo=0.0, lo_open=True)
    wts = np.asarray(weights)
    allowed = (f"a finite, non-negative real array of shape {ref.shape[:2]} with a positive "
               "sum")
    if wts.shape != ref.shape[:2] or not np.issubdtype(wts.dtype, np.number) or \
            np.iscomplexobj(wts):
        raise ParameterError("weights", f"{wts.dtype} array of shape {wts.shape}", allowed)
    wts = wts.astype(np.float64)
    if not np.all(np.isfinite(wts)) or (wts < 0).any() or not wts.sum() > 0:
        raise ParameterError("weights", f"array with min {np.nanmin(wts):g}, sum "
                             f"{np.nansum(wts):g}", allowed)
    wts = wts / wts.sum()
    err = (ref - tst) ** 2
    if err.ndim == 3:
        err = err.mean(axis=-1)
    return _psnr_from_mse(float(np.sum(wts * err)), rng)


# ---------------------------------------------------------------------------------------------
# SSIM
# ---------------------------------------------------------------------------------------------

def ssim_win_size(height: int, width: int) -> int | None:
    """SSIM window side: 7, or the largest odd number <= min(H, W); None below 3 px.

    Parameters
    ----------
    height, width : int
        Image size, in pixels.

    Returns
    -------
    side : int or None
        The window's side, in pixels.
    """
    side = min(height, width, SSIM_WIN_SIZE)
    if side % 2 == 0:
        side -= 1
    return side if side >= 3 else None


def ssim(reference, test, data_range: float | None = None, mask=None) -> float:
    """Mean structural similarity (Wang et al. 2004) through
    ``skimage.metrics.structural_similarity``, averaged over channels.

    Parameters
    ----------
    reference, test : array_like
        Finite real images of one shape, (H, W) or (H, W, C).
    data_range : float or None, optional
        ``L`` of SSIM's constants; None: from the reference (see the module docstring).
    mask : numpy.ndarray or None, optional
        bool (H, W): the mean of the full SSIM map over these pixels (see the module
        docstring); None: scikit-image's mean.

    Returns
    -------
    ssim : float
        ``nan`` when the image is smaller than 3 px on a side or the mask is empty.
    """
    from skimage.metrics import structural_similarity

    ref, tst = _check_pair(reference, test)
    m = _check_mask(mask, ref.shape)
    rng = _data_range(ref, data_range)
    win = ssim_win_size(ref.shape[0], ref.shape[1])
    if win is None or (m is not None and not m.any()):
        return math.nan
    channel_axis = -1 if ref.ndim == 3 else None
    if m is None:
        return float(structural_similarity(ref, tst, data_range=rng, win_size=win,
                                           channel_axis=channel_axis))
    return float(ssim_map(ref, tst, rng, win)[m].mean())


def ssim_map(ref: np.ndarray, tst: np.ndarray, data_range: float, win: int) -> np.ndarray:
    """scikit-image's full (H, W) SSIM map, averaged over channels (validated float inputs).

    Parameters
    ----------
    ref, tst : numpy.ndarray
        Validated float images of one shape, (H, W) or (H, W, C).
    data_range : float
        ``L`` of SSIM's constants.
    win : int
        Window side (:func:`ssim_win_size`).

    Returns
    -------
    ssim : numpy.ndarray
        (H, W) SSIM per pixel.
    """
    from skimage.metrics import structural_similarity

    channel_axis = -1 if ref.ndim == 3 else None
    _, full = structural_similarity(ref, tst, data_range=data_range, win_size=win,
                                    channel_axis=channel_axis, full=True)
    return full.mean(axis=-1) if full.ndim == 3 else full


# ---------------------------------------------------------------------------------------------
# FLIP
# ---------------------------------------------------------------------------------------------

def _flip_inputs(reference, test, ppd) -> tuple[np.ndarray, np.ndarray, float]:
    ref, tst = _check_pair(reference, test)
    ppd = check_range("ppd", ppd, 0.0, None, lo_open=True)
    for name, arr in (("reference", ref), ("test", tst)):
        if arr.ndim == 3 and arr.shape[2] not in (1, 3):
            raise ParameterError(name, f"array of shape {arr.shape}",
                                 "an (H, W), (H, W, 1) or (H, W, 3) image for FLIP")
        lo, hi = float(arr.min()), float(arr.max())
        if lo < 0.0 or hi > 1.0:
            raise ParameterError(name, f"array with values in [{lo:g}, {hi:g}]",
                                 "a display-referred image in [0, 1] for FLIP (LDR); see "
                                 "foveated_mi.render.to_display")

    def rgb(a):
        if a.ndim == 2:
            a = a[..., None]
        if a.shape[2] == 1:
            a = np.repeat(a, 3, axis=2)
        return np.ascontiguousarray(a, dtype=np.float32)

    return rgb(ref), rgb(tst), ppd


def flip_map(reference, test, *, ppd: float = 67.0) -> np.ndarray:
    """FLIP error map (Andersson et al. 2020, LDR, sRGB inputs) through ``flip_evaluator``.

    Inputs are validated first, since flip_evaluator exits the process on bad arguments.

    Parameters
    ----------
    reference, test : array_like
        Display-referred images in [0, 1] of one shape, (H, W), (H, W, 1) or (H, W, 3).
    ppd : float, optional
        Viewing condition, in pixels per degree.

    Returns
    -------
    error : numpy.ndarray
        float64 (H, W), in [0, 1].
    """
    import flip_evaluator

    ref, tst, ppd = _flip_inputs(reference, test, ppd)
    err, _, _ = flip_evaluator.evaluate(ref, tst, "LDR", inputsRGB=True, applyMagma=False,
                                        computeMeanError=False, parameters={"ppd": ppd})
    return np.asarray(err, dtype=np.float64).reshape(ref.shape[:2])


def flip(reference, test, *, ppd: float = 67.0, mask=None) -> float:
    """Mean FLIP error in [0, 1] (0: identical) over the pixels in ``mask``.

    Parameters
    ----------
    reference, test : array_like
        Images in [0, 1] of one shape; grey (H, W) images are compared as RGB with equal
        channels.
    ppd : float, optional
        The viewing condition in pixels per degree (67: a 0.7 m viewing distance from a 24" 4K
        monitor, FLIP's default).
    mask : numpy.ndarray or None, optional
        bool (H, W): the pixels to measure (None: all).

    Returns
    -------
    flip : float
        ``nan`` for an empty mask.
    """
    ref, _, _ = _flip_inputs(reference, test, ppd)
    m = _check_mask(mask, ref.shape)
    if m is not None and not m.any():
        return math.nan
    err = flip_map(reference, test, ppd=ppd)
    return float(err.mean() if m is None else err[m].mean())


# ---------------------------------------------------------------------------------------------
# Everything at once
# ---------------------------------------------------------------------------------------------

def compare(reference, test, *, gaze=None, theta=None, sigma_p=None,
            data_range: float | None = None, flip: bool = True,
            ppd: float = 67.0, eccentricity=None, fovea_deg: float = 5.0) -> dict[str, float]:
    """All metrics of ``test`` against ``reference`` as ``{key: float}`` with every key of
    :data:`COMPARE_KEYS` present (``nan`` where not computable), so CSV columns are stable:

    * ``psnr``, ``ssim``, ``flip``: full frame;
    * with ``gaze`` and ``theta``: ``*_fovea`` and ``*_periphery`` over :func:`fovea_mask`
      and its complement; with ``eccentricity`` instead (an (H, W) map in degrees, e.g.
      :func:`foveated_mi.viewer.eccentricity_map`), the fovea is the pixels within
      ``fovea_deg`` of the gaze;
    * with ``sigma_p`` too: ``psnr_eccentricity`` (:func:`eccentricity_weighted_psnr` with
      :func:`eccentricity_weights`, same data range).

    FLIP keys are ``nan`` when ``flip`` is False, and also when an image has values outside
    [0, 1] (FLIP is defined for display-referred images; call :func:`flip` for an error).
    """
    ref, tst = _check_pair(reference, test)
    if (gaze is None) != (theta is None):
        name, value = ("theta", theta) if theta is None else ("gaze", gaze)
        raise ParameterError(name, value, "given together with "
                             + ("gaze" if gaze is None else "theta") + " (both or neither)")
    if sigma_p is not None and gaze is None:
        raise ParameterError("sigma_p", sigma_p, "None unless gaze and theta are given")
    fovea = None
    if eccentricity is not None:
        ecc = np.asarray(eccentricity, dtype=np.float64)
        if ecc.shape != ref.shape[:2] or not np.all(np.isfinite(ecc)):
            raise ParameterError("eccentricity", f"<array of shape {ecc.shape}>",
                                 f"finite degrees of shape {ref.shape[:2]}")
        fovea = ecc < check_range("fovea_deg", fovea_deg, 0.0, 180.0, lo_open=True)
    elif gaze is not None:
        fovea = fovea_mask(ref.shape, gaze, theta)
    rng = _data_range(ref, data_range)
    out = dict.fromkeys(COMPARE_KEYS, math.nan)
    out["psnr"] = psnr(ref, tst, rng)
    out["ssim"] = ssim(ref, tst, rng)
    do_flip = bool(flip) and ref.min() >= 0.0 and ref.max() <= 1.0 and \
        tst.min() >= 0.0 and tst.max() <= 1.0
    fmap = flip_map(ref, tst, ppd=ppd) if do_flip else None
    if fmap is not None:
        out["flip"] = float(fmap.mean())
    if fovea is not None:
        win = ssim_win_size(ref.shape[0], ref.shape[1])
        smap = ssim_map(ref, tst, rng, win) if win is not None else None
        for tag, m in (("fovea", fovea), ("periphery", ~fovea)):
            out[f"psnr_{tag}"] = psnr(ref, tst, rng, mask=m)
            if m.any():
                if smap is not None:
                    out[f"ssim_{tag}"] = float(smap[m].mean())
                if fmap is not None:
                    out[f"flip_{tag}"] = float(fmap[m].mean())
        if sigma_p is not None and gaze is not None:
            out["psnr_eccentricity"] = eccentricity_weighted_psnr(
                ref, tst, eccentricity_weights(ref.shape, gaze, theta, sigma_p), rng)
    return out


# ---------------------------------------------------------------------------------------------
# Temporal instability (flicker) per ring of eccentricity
# ---------------------------------------------------------------------------------------------

#: Ring edges in degrees of eccentricity of the studies' flicker columns: 0-5 (the fovea at
#: the default ``fovea_deg``), 5-10, 10-20, 20-35 and 35-180 (the rest of any field of view;
#: eccentricity never exceeds 180 degrees).
FLICKER_RINGS_DEG = (0.0, 5.0, 10.0, 20.0, 35.0, 180.0)


def flicker_ring_columns(rings=FLICKER_RINGS_DEG) -> tuple[str, ...]:
    """Column names of the rings between consecutive ``rings`` edges.

    Parameters
    ----------
    rings : sequence of float, optional
        Ring edges in degrees, at least two, non-negative and strictly increasing.

    Returns
    -------
    columns : tuple of str
        ``flicker_<lo>_<hi>`` in degrees, a decimal point written ``p`` (``flicker_0_5``,
        ``flicker_5_10``, ... for :data:`FLICKER_RINGS_DEG`).
    """
    edges = _check_rings(rings)
    return tuple(f"flicker_{lo:g}_{hi:g}".replace(".", "p")
                 for lo, hi in zip(edges, edges[1:]))


class TemporalInstability(NamedTuple):
    """What :func:`temporal_instability` returns (display values, the images' own units)."""

    #: RMS per ring, shape ``(len(edges) - 1,)``; nan for a ring no pixel fell in.
    rings: np.ndarray
    #: RMS over the periphery (eccentricity ``>= fovea_deg``); nan when it is empty or no
    #: eccentricity was given.
    periphery: float
    #: RMS over every pixel of the frame.
    frame: float
    #: The ring edges in degrees.
    edges: np.ndarray

    def columns(self) -> dict[str, float]:
        """``{"flicker": frame, "flicker_periphery": periphery, "flicker_<lo>_<hi>": ring}``,
        the names of :func:`flicker_ring_columns`."""
        return {"flicker": self.frame, "flicker_periphery": self.periphery,
                **{c: float(v) for c, v in zip(flicker_ring_columns(self.edges), self.rings)}}


def _check_rings(rings) -> np.ndarray:
    allowed = ("at least 2 finite, non-negative, strictly increasing ring edges in degrees "
               "(e.g. (0, 5, 10, 20, 35, 180))")
    try:
        edges = np.asarray(rings, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError("rings", rings, allowed) from None
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.isfinite(edges)) or \
            edges[0] < 0.0 or not np.all(np.diff(edges) > 0.0):
        raise ParameterError("rings", rings, allowed)
    return edges


#: The flicker columns of a sequence row: the whole frame, the periphery (outside the
#: fovea), then each ring of :data:`FLICKER_RINGS_DEG`.
FLICKER_KEYS = ("flicker", "flicker_periphery", *flicker_ring_columns())


def _frame_list(name: str, frames, ndims: tuple[int, ...], what: str) -> list[np.ndarray]:
    """``frames`` (an (F, ...) array or a sequence of per-frame arrays) as a list of arrays,
    without stacking a sequence (a long sequence at full size stays in its own frames)."""
    allowed = f"a sequence of {what}"
    if isinstance(frames, np.ndarray):
        if frames.ndim - 1 not in ndims:
            raise ParameterError(name, f"{frames.dtype} array of shape {frames.shape}",
                                 allowed)
        return list(frames)
    try:
        out = [np.asarray(f) for f in frames]
    except TypeError:
        raise ParameterError(name, frames, allowed) from None
    return out


def _check_sequence(name: str, frames) -> list[np.ndarray]:
    what = "at least 2 real (H, W) or (H, W, C) frames of one shape"
    seq = _frame_list(name, frames, (2, 3), what)
    if len(seq) < 2:
        raise ParameterError(name, f"{len(seq)} frame{'s' * (len(seq) != 1)}",
                             what + " (a change needs two frames)")
    shape = seq[0].shape
    for k, f in enumerate(seq):
        if f.ndim not in (2, 3) or 0 in f.shape or f.shape != shape or not (
                np.issubdtype(f.dtype, np.floating) or np.issubdtype(f.dtype, np.integer)):
            raise ParameterError(f"{name}[{k}]", f"{f.dtype} array of shape {f.shape}",
                                 f"{what} (frame 0: {shape})")
        bad = int(np.count_nonzero(~np.isfinite(f)))
        if bad:
            raise ParameterError(f"{name}[{k}]", f"array with {bad} NaN/inf values",
                                 "finite values")
    return seq


def _check_eccentricity(ecc, n: int, hw: tuple[int, int]) -> list[np.ndarray] | None:
    if ecc is None:
        return None
    allowed = (f"finite degrees >= 0: one (H, W) = {hw} map for every frame, or one per frame "
               f"({n} of them)")
    if isinstance(ecc, np.ndarray) and ecc.ndim == 2:
        maps = [ecc] * n
    else:
        maps = _frame_list("eccentricity_deg", ecc, (2,), allowed)
        if len(maps) != n:
            raise ParameterError("eccentricity_deg", f"{len(maps)} maps", allowed)
    for k, m in enumerate(maps):
        if m.shape != hw or not np.issubdtype(m.dtype, np.number) or np.iscomplexobj(m):
            raise ParameterError("eccentricity_deg", f"{m.dtype} array of shape {m.shape}",
                                 allowed)
        m64 = m.astype(np.float64)
        if not np.all(np.isfinite(m64)) or (m64 < 0).any():
            raise ParameterError("eccentricity_deg", f"map {k} with values in "
                                 f"[{np.nanmin(m64):g}, {np.nanmax(m64):g}]", allowed)
    return [m.astype(np.float64, copy=False) for m in maps]


def temporal_instability(test_frames, ref_frames, eccentricity_deg=None,
                         rings=FLICKER_RINGS_DEG, *, fovea_deg: float = 5.0
                         ) -> TemporalInstability:
    r"""Temporal instability (flicker) of a sequence against its per-frame reference, per ring
    of eccentricity: the root mean square, over a region's pixels, the channels and every
    pair of consecutive frames, of :math:`(t_k - t_{k-1}) - (r_k - r_{k-1})`, what the test
    changes beyond what the reference changes (the scene's own motion cancels, and a still
    error is no flicker). A pixel belongs to the ring of its eccentricity in frame :math:`k`,
    the later frame of the pair.

    Parameters
    ----------
    test_frames : (F, H, W) or (F, H, W, C) array_like, or a sequence of F frames
        The sequence to score, F >= 2, display-referred (e.g.
        :func:`foveated_mi.render.to_display`), finite. A sequence of frames is read frame by
        frame, never stacked.
    ref_frames : same shape as ``test_frames``
        The reference of each frame (its own camera and time).
    eccentricity_deg : (H, W) array, (F, H, W) array or sequence of F (H, W) arrays, optional
        Each pixel's eccentricity in degrees from the gaze ray: one map for every frame (a
        still gaze) or one per frame (e.g. :func:`foveated_mi.viewer.eccentricity_map` at each
        frame's gaze). None: only the whole frame's figure is computed (``rings`` and
        ``periphery`` are nan).
    rings : sequence of float, optional
        Ring edges in degrees, at least two, non-negative and strictly increasing; ring ``j``
        holds ``rings[j] <= e < rings[j + 1]``, the last ring its upper edge too. Pixels
        outside ``[rings[0], rings[-1]]`` belong to no ring. Default
        :data:`FLICKER_RINGS_DEG`.
    fovea_deg : float, optional
        The fovea's radius in degrees, in (0, 180]: the periphery is every pixel at
        ``e >= fovea_deg`` (the complement of :func:`compare`'s fovea ``e < fovea_deg``).

    Returns
    -------
    TemporalInstability
        ``rings`` (one RMS per ring, nan for a ring no pixel fell in), ``periphery`` (nan when
        empty), ``frame`` (the whole frame) and ``edges``; ``columns()`` names them as the
        study's columns. 0 exactly when ``test_frames`` equals ``ref_frames``, or differs from
        it by the same error in every frame.

    Bad input (fewer than 2 frames, shapes that differ, non-finite values, a bad eccentricity
    map, ring edges or fovea radius) raises a one-line ``ParameterError``.
    """
    test, ref, eccs, edges, fovea_deg = _flicker_inputs(test_frames, ref_frames,
                                                        eccentricity_deg, rings, fovea_deg)
    sums = _FlickerSums(len(edges) - 1)
    prev = test[0].astype(np.float64) - ref[0]
    for k in range(1, len(test)):
        err = test[k].astype(np.float64) - ref[k]
        d = err - prev
        prev = err
        sq = d * d
        if sq.ndim == 3:
            sq = sq.mean(axis=-1)               # every pixel has all C channels
        sums.add(sq, None if eccs is None else eccs[k], edges, fovea_deg)
    ring_rms = np.array([_rms(a, b) for a, b in zip(sums.ring_se, sums.ring_n)])
    periphery = _rms(sums.per_se, sums.per_n) if eccs is not None else math.nan
    return TemporalInstability(ring_rms, periphery, _rms(sums.all_se, sums.all_n), edges)


def temporal_instability_map(test_frames, ref_frames) -> np.ndarray:
    r"""Where a sequence flickers: :func:`temporal_instability` per pixel, the root mean
    square over the channels and every pair of consecutive frames of
    :math:`(t_k - t_{k-1}) - (r_k - r_{k-1})`, so that the square root of the mean of the map's
    squares over the frame is ``temporal_instability(...).frame``.

    Parameters
    ----------
    test_frames, ref_frames : (F, H, W) or (F, H, W, C) array_like, or sequences of F frames
        As :func:`temporal_instability`'s: display-referred, finite, F >= 2, one shape.

    Returns
    -------
    numpy.ndarray
        (H, W) float64, in display values; 0 where the test changes as the reference does.

    Bad input raises :func:`temporal_instability`'s one-line ``ParameterError``.
    """
    test, ref, _, _, _ = _flicker_inputs(test_frames, ref_frames, None, FLICKER_RINGS_DEG,
                                         5.0)
    total = np.zeros(test[0].shape[:2])
    prev = test[0].astype(np.float64) - ref[0]
    for k in range(1, len(test)):
        err = test[k].astype(np.float64) - ref[k]
        sq = np.square(err - prev)
        prev = err
        total += sq.mean(axis=-1) if sq.ndim == 3 else sq
    return np.sqrt(total / (len(test) - 1))


def _flicker_inputs(test_frames, ref_frames, eccentricity_deg, rings, fovea_deg):
    """:func:`temporal_instability`'s arguments, checked (one line on bad input)."""
    test = _check_sequence("test_frames", test_frames)
    ref = _check_sequence("ref_frames", ref_frames)
    if len(ref) != len(test) or ref[0].shape != test[0].shape:
        raise ParameterError("ref_frames", f"{len(ref)} frames of shape {ref[0].shape}",
                             f"as many frames as the test frames, of their shape: "
                             f"{len(test)} of {test[0].shape}")
    edges = _check_rings(rings)
    fovea_deg = check_range("fovea_deg", fovea_deg, 0.0, 180.0, lo_open=True)
    eccs = _check_eccentricity(eccentricity_deg, len(test), test[0].shape[:2])
    return test, ref, eccs, edges, fovea_deg


def _rms(se: float, n: float) -> float:
    return math.sqrt(se / n) if n > 0 else math.nan


class _FlickerSums:
    """Squared changes summed per ring, over the periphery and over the frame, with counts."""

    def __init__(self, n_rings: int):
        self.ring_se, self.ring_n = np.zeros(n_rings), np.zeros(n_rings)
        self.per_se = self.per_n = self.all_se = self.all_n = 0.0

    def add(self, sq: np.ndarray, e: np.ndarray | None, edges: np.ndarray,
            fovea_deg: float) -> None:
        """One pair of frames: ``sq`` per pixel, ``e`` the later frame's eccentricity."""
        self.all_se += float(sq.sum())
        self.all_n += sq.size
        if e is None:
            return
        n_rings = len(self.ring_se)
        j = np.searchsorted(edges, e, side="right") - 1
        j[e == edges[-1]] = n_rings - 1         # the last ring holds its upper edge
        inside = (j >= 0) & (j < n_rings)
        self.ring_se += np.bincount(j[inside], weights=sq[inside], minlength=n_rings)
        self.ring_n += np.bincount(j[inside], minlength=n_rings)
        periphery = e >= fovea_deg
        self.per_se += float(sq[periphery].sum())
        self.per_n += int(np.count_nonzero(periphery))
