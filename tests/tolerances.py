r"""Float tolerances of the tests, derived from the arithmetic instead of one machine's output.

Dr.Jit's LLVM backend compiles for the host CPU. Its elementwise kernels round the same way
everywhere (plain ``fadd``/``fmul``/``fdiv`` without fast-math flags, ``llvm.fma`` only where
the code asks for one; the vector width does not change an element's result), but the order
of a reduction does change with the vector width and the thread count (``dr.sum``'s blocks
and lanes, ``scatter_add`` atomics), and a CUDA build may contract a multiply-add in one
kernel and not in another. Two float32 evaluations of the same formula in different orders
agree only to within their rounding errors: these helpers bound those errors from what is
computed (the number of roundings, the sizes of the terms), so that a bound holds on any
x86-64 CPU (and on CUDA) and still fails on a real bug. (Dr.Jit divides by a literal as a
product with its rounded reciprocal: two roundings.)

**Model** (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §2.2, §3.1,
§3.5, §4.2). A float32 operation rounded to nearest returns ``(a op b)(1 + d)`` with
``|d| <= U = 2**-24``, the *unit roundoff*. (``np.finfo(np.float32).eps = 2**-23 = 2 U`` is
the spacing of float32 numbers at 1, one ulp; a correctly rounded result is within half an
ulp, hence ``U``.) An FMA rounds once where a separate multiply and add round twice, so
counting every multiply and every add as one rounding covers both compilations. A path of
``k`` roundings gives a relative error of at most

.. math::   \gamma_k = \frac{k U}{1 - k U}.

- A sum of ``n`` terms in *any* order (sequential, pairwise, SIMD lanes, per-thread blocks,
  atomics): ``|fl(sum) - sum| <= gamma(n - 1) * sum |x_i|`` (every term passes through at
  most ``n - 1`` additions). NumPy's pairwise float32 sum needs only ``ceil(log2 n)``, but
  the worst case covers every order, which is the point here.
- A dot product of ``n`` terms: ``gamma(n) * sum |a_i b_i|`` (one more rounding for the
  products). A dot product of float32 arrays computed in float64 (:func:`dot`) is exact in
  its products (24 + 24 bits < 53) and its sum errs by ``gamma64(n - 1) sum |a_i b_i|``,
  about ``n 2**-53``: below one float32 rounding for any size used here.
- A linear map evaluated as a chain of stages, each output of stage ``l`` a float32 sum of
  ``m_l`` weighted inputs (plus a division or a scale): the computed output errs by at most
  ``gamma(k) (|A| |x|)_i`` with ``k = sum_l (m_l + 1)``, the roundings along the longest path
  (``|A|``: the map with every weight replaced by its absolute value). A 5x5 filter level with
  normalised weights is 25 FMA accumulations and one division: 26 roundings.
- Transcendentals (``exp``, ``log``, ``pow``) of Dr.Jit and of libm are not correctly rounded;
  each counts as :data:`TRANSCENDENTAL` roundings.

Where a bound needs ``|A| |x|`` and only ``A x`` is at hand, the tests pass the sum of absolute
terms they have (e.g. ``sum |(A x)_i y_i|``); for filters with non-negative weights applied to
non-negative values the two are equal.

**Statistical tolerances** (Monte Carlo means, PSNR margins, finite differences) are not
rounding errors and do not come from here: they come from each test's own standard errors.
"""
from __future__ import annotations

import math

import numpy as np

#: Unit roundoff of float32 round-to-nearest (half an ulp at 1): ``np.finfo(np.float32).eps / 2``.
U = 2.0 ** -24
#: Unit roundoff of float64.
U64 = 2.0 ** -53
#: Roundings charged for one transcendental function (``exp``, ``log``, ``sqrt`` of a
#: non-correctly-rounded implementation, ``pow`` as ``exp(y log x)``): Dr.Jit's float32
#: ``exp``/``log`` are accurate to about 1-2 ulp (2-4 U), and ``pow`` multiplies the log's error
#: by ``|y|``; 8 U covers these for ``|y| <= 2.2`` (the tone curves).
TRANSCENDENTAL = 8


def gamma(k: float, u: float = U) -> float:
    """``gamma_k = k u / (1 - k u)``: the relative error bound of ``k`` roundings."""
    k = float(k)
    if k * u >= 1.0:
        raise ValueError(f"{k} roundings of {u:g} bound nothing")
    return k * u / (1.0 - k * u)


def _abs64(a) -> np.ndarray:
    return np.abs(np.asarray(a, dtype=np.float64))


def dot(a, b) -> float:
    """``<a, b>`` in float64 (NumPy): exact products of float32 inputs, a float64 sum."""
    return float(np.dot(np.asarray(a, np.float64).ravel(), np.asarray(b, np.float64).ravel()))


def dot_bound(a, b, depth: float = 0, summed: str = "float64") -> float:
    """Error bound of ``<a, b>`` where each element of ``a`` (or ``b``) carries ``depth``
    float32 roundings of its own (the chain that computed it) and the dot product is
    ``summed`` in ``"float64"`` (:func:`dot`: exact products, a float64 sum of ``n`` terms) or in
    ``"float32"`` in any order (``n`` more roundings: the product and ``n - 1`` additions, as
    ``dr.sum`` on any backend).

    ``gamma(depth + n) * sum |a_i b_i|`` (float32 sum), or
    ``gamma(depth) * S + gamma64(n) * S`` with ``S = sum |a_i b_i|`` (float64 sum)."""
    s = float(np.sum(_abs64(a).ravel() * _abs64(b).ravel()))
    n = np.size(a)
    if summed == "float64":
        return gamma(depth) * s + gamma(n, U64) * s
    if summed == "float32":
        return gamma(depth + n) * s
    raise ValueError(f"summed = {summed!r}: expected 'float64' or 'float32'")


def transpose_bound(ax, y, x, aty, depth: float, adjoint_depth: float | None = None,
                    summed: str = "float64") -> float:
    """Bound of ``|<A x, y> - <x, A^T y>|`` for a float32 map ``A`` and its adjoint, each
    output of ``A x`` the end of a chain of ``depth`` roundings and each of ``A^T y`` of
    ``adjoint_depth`` (default: the same; see the module docstring for how to count them):
    ``dot_bound(ax, y, depth) + dot_bound(x, aty, adjoint_depth)``. In exact arithmetic the
    two sides are equal, and with the map's weights held the float32 weights are the same in
    both passes (the same code on the same values), so only the evaluation's roundings
    separate them.

    The sums of absolute terms are those of the computed products, ``sum |(A x)_i y_i|``: the
    worst case needs ``sum |y_i| (|A| |x|)_i``, larger where the map's sums cancel; the
    gradient tests measured ``A |x|`` at 2 to 5 times ``|A x|`` on random-sign inputs, while
    their errors stay below 1 % of these bounds."""
    adjoint_depth = depth if adjoint_depth is None else adjoint_depth
    return dot_bound(ax, y, depth, summed) + dot_bound(x, aty, adjoint_depth, summed)


def chain_bound(scale, depth: float) -> np.ndarray:
    """Elementwise bound ``gamma(depth) * |scale|`` of a value computed by ``depth`` float32
    roundings, where ``scale`` is the sum of the absolute terms of the value's formula (its
    own magnitude when nothing cancels). For two float32 evaluations of the same formula in
    different orders, count the roundings of both sides."""
    return gamma(depth) * _abs64(scale)


def assert_within(got, want, bound, what: str = "") -> None:
    """``|got - want| <= bound`` elementwise (bound broadcast), with the worst ratio in the
    message; ``bound`` from :func:`chain_bound` and friends."""
    got64, want64 = np.broadcast_arrays(np.asarray(got, np.float64), np.asarray(want, np.float64))
    err = np.abs(got64 - want64)
    bound = np.broadcast_to(np.asarray(bound, np.float64), err.shape)
    bad = ~(err <= bound)
    if bad.any():
        i = np.unravel_index(np.argmax(np.where(bad, err - bound, -np.inf)), err.shape)
        raise AssertionError(
            f"{what}: {int(bad.sum())} of {err.size} values outside the rounding bound; worst "
            f"at {tuple(int(j) for j in i)}: got {got64[i]!r}, want {want64[i]!r}, error "
            f"{err[i]:.3g} > bound {bound[i]:.3g}")


# -- roundings of this package's stages (the derivative passes of foveated_mi) -----------------
#
# Counted along the longest path of a tangent (forward mode) and of an adjoint (reverse mode).
# Filter weights are computed from held (detached) values by the same code in both passes, so
# the two passes use the same float32 weights and only the evaluation's roundings count.

#: One 5x5 level of a normalised edge-stopping filter (à-trous): 25 FMA accumulations and the
#: division by the weight sum (the transpose divides first, then accumulates the 25 taps).
FILTER_LEVEL = 25 + 1
#: One SVGF level: the à-trous level in residual form, ``x(p) + sum w (x(q) - x(p)) / W``:
#: the subtraction and the final addition on top.
SVGF_LEVEL = 25 + 3
#: A guided cascade level: 25 FMA taps, the estimate's division, one FMA of the blend.
GUIDED_LEVEL = 25 + 2
#: A tone curve (or its inverse) differentiated at the primal values: the chain of its
#: rational and power derivatives, the quotient rule's products and sums included.
TONE_CURVE = 16


def guided_constant_depth(levels: int = 5) -> int:
    """Roundings of the guided reconstruction's output against its exact value when every
    site holds the same colour (a convex combination of site values): per level the
    numerator's 25 FMA taps, the sample weights' 25 products and 25 sums (numerator and
    denominator err separately, so their ratio is not exact) and the division; the blend
    weights ``tau prod (1 - tau)`` 2 per level, the blend's FMAs one per level, the site's
    ``value * w`` and the fallback's FMA."""
    return levels * (25 + 2 * 25 + 1) + 2 * (levels + 1) + (levels + 1) + 2


def gauss_count(r2: float) -> int:
    """Pixels within squared distance ``r2`` of a pixel (lattice points of a disk)."""
    r = int(math.isqrt(max(int(r2), 0)))
    i = np.arange(-r - 1, r + 2)
    return int(((i[:, None] ** 2 + i[None, :] ** 2) <= r2).sum())


def reconstruction_depth(method: str, nearest_xy, traced, width: int, levels: int = 5
                         ) -> tuple[int, int]:
    """``(forward, reverse)`` roundings of :func:`foveated_mi.reconstruct.reconstruct` for one
    frame: ``nearest_xy`` ``(n, 2)`` site coordinates of each pixel (-1 without a site, as
    ``FoveatedIntegrator.buffer("nearest")``), ``traced`` ``(n,)`` the site mask.

    - The Voronoi fill is a gather; its adjoint scatter-adds every pixel of a site's cell into
      the site in float32: ``cell - 1`` additions (``cell`` the largest cell).
    - ``sibson`` sums its disks in float64 and rounds once; its adjoint scatter-adds into each
      filled pixel once per disk holding it: at most ``G`` terms, the pixels within the
      largest site distance (:func:`gauss_count`), then the fill's adjoint.
    - ``discrete_sibson``, ``fast_sibson``: float64 sums rounded once; the adjoint's
      ``1 / count`` (and the plus pixels' reads) a few more, then the fill's adjoint.
    - ``stochastic`` copies one site per pixel: its adjoint adds at most every untraced pixel
      into one site.
    - ``guided``: :data:`GUIDED_LEVEL` per level both ways, the division of level -1 and the
      Voronoi fallback's blend, then the fill's adjoint.
    """
    xy = np.asarray(nearest_xy).reshape(-1, 2)
    traced = np.asarray(traced, bool).ravel()
    has = xy[:, 0] >= 0
    site = (xy[:, 1] * width + xy[:, 0]).astype(np.int64)
    cell = int(np.bincount(site[has]).max()) if has.any() else 1
    px, py = np.arange(xy.shape[0]) % width, np.arange(xy.shape[0]) // width
    d2 = ((px - xy[:, 0]) ** 2 + (py - xy[:, 1]) ** 2)[has]
    disk = gauss_count(int(d2.max()) if d2.size else 0)
    fill = cell - 1
    forward, reverse = {
        "voronoi": (0, fill),
        "sibson": (1, disk + 1 + fill),
        "discrete_sibson": (1, 3 + fill),
        "fast_sibson": (1, 4 + fill),
        "stochastic": (0, int((~traced).sum())),
        "guided": (GUIDED_LEVEL * levels + 3, GUIDED_LEVEL * levels + 3 + fill),
    }[method]
    return forward, reverse
