"""The ``foveal`` formation: denoise in a log-polar buffer around the gaze, then warp once.

The passes after the trace cost what the rays cost. With ``sampling_law = "polar"`` the frame
traces the pixel under each cell of the log-polar buffer
(:func:`foveated_mi.frame.cells.foveal_grid`, sized by ``ray_budget``) and every pixel
of its full-resolution disc. With ``sampling_law = "flat"`` (``buffer`` space only) the
buffer is an even grid at the budget's density and there is no disc
(:mod:`foveated_mi.kernels.flat`): dynamic resolution with temporal accumulation from the same
passes. Where the frame keeps its geometry and history is ``foveal_space``:

``buffer`` (the ``vr`` preset)
    On the buffer's *samples*: its cells outside the disc, then the disc's pixels
    (:mod:`foveated_mi.frame.buffer_space`). The plan casts the G-buffer at the samples
    only, develops the traced values straight onto the samples
    (:func:`foveated_mi.frame.shading.to_samples`) and reprojects the history sample to
    sample; nothing is film-sized but the image.
``film``
    On the film's pixels: a full-resolution G-buffer, the history resolved on the traced
    pixels as the ``film`` formation does (Fig. 4), the cells gathered from their pixels, and
    the albedo multiplied back per pixel after the warp (``demodulate``).

Then, in either:

1. **History resolve** (Fig. 4): the traced values blended with the reprojected history,
   so a moving head keeps it. A cell or disc pixel that holds nothing yet holds a non-finite
   value that every filter tap and the warp leave out.
2. **Denoising in the buffer** (§3.5): the registered denoiser on the buffer's grid, in the
   domain it declares (irradiance with ``demodulate``: :mod:`foveated_mi.frame.domain`);
   taps wrap around in angle, and a denoiser that sees a plain image (a network) gets the
   buffer padded across the seam at angle 0 (:func:`_padded`). The cells off the film
   (about a third of them with the gaze at the centre of a square film) are the denoiser's
   ``region`` complement: a filter skips them, and they hold no value that a tap reads.
3. **One warp to the film**: each pixel's continuous cell coordinates, bilinear over the
   cells that hold a value (wrapping in angle, clamping radially). In the fovea disc every
   pixel was traced: it shows its own resolved value, blended into the warp across the
   disc's last :data:`SEAM` pixels.

There is no Jump Flooding and no interpolation on the film. Every weight comes from the
buffer's geometry, the G-buffer or detached values, so the image is a fixed function of the
traced values, and the gradient pass differentiates it like the ``film`` formation (gathers
and held filter levels).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import drjit as dr
import mitsuba as mi

from ..kernels.pixels import gather4, packet
from ..kernels.taps import Surface, surface_energy
from ..kernels.buffers import GBuffer, Resolved
from ..kernels.grid import Grid, wrap_padding
from ..kernels.flat import FlatGrid
from ..kernels.polar import PolarGrid
from ..postprocess import DENOISERS, DenoiseInput, Denoised
from ..postprocess.registry import as_denoised
from ..timing import StageTimer
from . import buffer_space as _buffer_space
from .cells import snapped_pixels
from . import domain
from . import reproject as _reproject
from .film import film_stats
from .formation import FormationInput, Formed, register_formation
from .post import denoise_in_domain, runs
from .settings import DenoiseSettings, DomainSettings
from .shading import ShadingBuffer

#: Pixels over which the fovea's own values blend into the warped buffer at the disc's edge.
SEAM = 2.0

#: The buffers it returns on the film's grid (the others are on the buffer's).
ON_FILM = ("traced", "shading", "shading_mask", "history_count", "resampled", "image")

#: With ``foveal_space = "buffer"``: the buffers on the samples (cells, then the disc's patch).
SAMPLE_BUFFERS = ("traced", "shading", "shading_mask", "history_count", "resampled", "sample_on",
              "sample_pixel", "position", "normal", "depth", "hit", "reprojection_map")


@dataclass(frozen=True)
class FovealSettings:
    """What the foveal formation reads, with the buffer it derives once per film (the gaze
    enters as an input array). Hashable: the key of its recording."""
    max_history: float
    domain: DomainSettings
    denoise: DenoiseSettings
    upsampling: str            #: ``foveal_upsampling``
    space: str                 #: ``foveal_space``
    disc: str                  #: ``foveal_disc``
    #: the samples (cells outside the disc, then the disc's patch) of the film and budget
    layout: _buffer_space.SampleLayout
    #: the buffer's grid (without the rings inside the disc in ``buffer`` space; an even
    #: grid with ``sampling_law = "flat"``)
    grid: PolarGrid | FlatGrid
    #: ``foveal_taa``: this frame's weight in what a cell shows (1: its denoised value)
    taa: float = 1.0
    #: ``foveal_contrast``: the cells' unsharp gain before the warp (0: none)
    contrast: float = 0.0
    #: the denoiser on the disc's patch (``foveal_disc_iterations``, ...; None: ``denoise``)
    disc_denoise: DenoiseSettings | None = None
    #: the same where the camera moved (``foveal_disc_iterations_moving``,
    #: ``sigma_luminance_moving``; None: as still)
    disc_denoise_moving: DenoiseSettings | None = None
    #: the buffer's denoiser where the camera moved (``sigma_luminance_moving``; None: as
    #: still)
    denoise_moving: DenoiseSettings | None = None
    #: the history's cap where the camera moved (``max_history_moving``; 0: as still)
    max_history_moving: float = 0.0


def foveal_buffer_grid(width: int, height: int, s: FovealSettings) -> PolarGrid:
    """The buffer's grid.

    Parameters
    ----------
    width, height : int
        The film's size (unused: the grid is in ``s``).
    s : FovealSettings
        The formation's settings.

    Returns
    -------
    grid : PolarGrid
        ``s.grid``.
    """
    return s.grid


def _cells(resolved: Resolved, gb: GBuffer, q: mi.UInt32, has: mi.Bool):
    """Each cell's resolved samples (radiance) and G-buffer, from its pixel."""
    value = dr.select(has, dr.gather(mi.Color3f, resolved.shading, q, has), dr.nan)
    res = Resolved(value, has, dr.gather(mi.Float, resolved.count, q, has),
                   dr.zeros(mi.Bool, dr.width(q)), dr.gather(mi.Float, resolved.moment2, q, has))
    cgb = _gather(gb, q, has)
    return res, cgb._replace(hit=cgb.hit & has)


def _working(res: Resolved, gb: GBuffer, d) -> mi.Color3f:
    """The working values of resolved samples (irradiance with ``demodulate``; non-finite
    where they hold none), for ``gb`` gathered at the same samples."""
    return dr.select(res.mask, domain.to_irradiance(res.shading, gb, d), dr.nan)


def _gather(bundle, index: mi.UInt32, active: mi.Bool | bool = True):
    """Every buffer of a named bundle (a ``GBuffer``, ``Resolved``) at ``index`` (None stays
    None)."""
    return type(bundle)(*(None if v is None else dr.gather(type(v), v, index, active)
                          for v in bundle))


def _denoise(image: mi.Color3f, res: Resolved, cgb: GBuffer, grid: Grid, s: FovealSettings,
             grad_pass: bool, region: mi.Bool | None = None,
             ds: DenoiseSettings | None = None, kept=None, keep: bool = False) -> Denoised:
    """The registered denoiser (``ds``, else the buffer's) on working values ``image``
    (irradiance with ``demodulate``), in the domain it declares; returns working values.
    ``res``: the resolved samples behind them, in radiance as the film's are, so that their
    mean and second moment give the noise's variance in one domain. ``region``: the cells on
    the film, the only ones the warp reads (a filter skips the others). ``kept``, ``keep``:
    what the denoiser kept of this G-buffer, and whether it holds (:class:`DenoiseInput`)."""
    ds = s.denoise if ds is None else ds
    entry, d = DENOISERS[ds.name], s.domain
    if not runs(ds, grad_pass):
        return Denoised(image)
    ctx = DenoiseInput(image, cgb, res, dr.arange(mi.UInt32, grid.size), grid.width,
                       grid.height, ds.options, grad_pass, None, grid, region, kept, keep)
    call = entry.fn if entry.grid_aware else _padded(entry.fn, grid)
    if entry.domain == "irradiance":
        return denoise_in_domain(call, entry.domain, ctx, image, d)
    out = denoise_in_domain(call, entry.domain, ctx, domain.to_radiance(image, cgb, d), d,
                            on=res.mask)
    return out._replace(image=domain.to_irradiance(out.image, cgb, d))


#: Columns of the other side added on each side of the buffer's angle axis for a denoiser
#: that sees a plain image (a network): its view across the seam at angle 0.
PAD = 32


def _padded(fn, grid: Grid):
    """``fn`` on the buffer padded across its wrapped angle axis, its result cropped back,
    for a denoiser that knows no neighbour rule: the seam at angle 0 is then no image edge
    to it. A grid that does not wrap (the disc's patch) is a plain image already: ``fn``."""
    if not grid.wrap_x:
        return fn
    padded, source, back = wrap_padding(grid, PAD)

    def pad(v):
        return None if v is None else dr.gather(type(v), v, source)

    def call(ctx: DenoiseInput) -> Denoised:
        wide = ctx._replace(
            image=pad(ctx.image), gbuffer=_gather(ctx.gbuffer, source),
            resolved=_gather(ctx.resolved, source),
            nearest=dr.arange(mi.UInt32, padded.size), width=padded.width,
            height=padded.height, samples=pad(ctx.samples), grid=padded,
            region=pad(ctx.region))
        return _gather(as_denoised(fn(wide)), back)
    return call


def _disc_patch(resolved: Resolved, gb: GBuffer, index: mi.UInt32, on: mi.Bool, side: int,
                s: FovealSettings, grad_pass: bool) -> mi.Color3f:
    """``foveal_disc = "denoised"``: the disc's square patch of ``side`` x ``side`` pixels
    (``index`` into ``resolved`` and ``gb``; ``on`` where the pixel's centre lies in the
    disc) through the frame's denoiser, as the cells are; radiance, in patch order. The
    patch is a plain image of full-resolution pixels: no seam, no padding. It keeps nothing
    of a still view's G-buffer: its levels are a small share of a still frame's filter, and
    their energies would hold 19 MB more at 1024² (the cells' hold 42 MB)."""
    pr = _gather(resolved, index, on)
    has = on & pr.mask
    pgb = _gather(gb, index, on)
    pgb = pgb._replace(hit=pgb.hit & has)
    res = Resolved(pr.shading, has, pr.count, dr.zeros(mi.Bool, side * side), pr.moment2)
    out = _denoise(_working(res, pgb, s.domain), res, pgb, Grid(side, side), s, grad_pass, on,
                   s.disc_denoise)
    return domain.to_radiance(out.image, pgb, s.domain, clamp=True)


def fill_cells(res: Resolved, grid: Grid, radius: int, targets: mi.Bool | bool = True
               ) -> Resolved:
    r"""Each cell without a value given its neighbours' (``foveal_interleave``: a cell whose
    turn it was not, with no history yet), before the denoiser, so that the denoiser sees a
    whole grid: the tent-weighted mean of the values (and of the second moments) of the cells
    that hold one within ``radius`` cells each way (wrapping in angle), counted as the
    samples behind that mean, :math:`(\sum w n)^2 / \sum w^2 n`. Linear in the values, with
    constant weights: a filled cell's gradient goes to the cells it read.

    Parameters
    ----------
    res : Resolved
        The cells: values (non-finite where none), mask, counts, second moments.
    grid : Grid
        The buffer's grid.
    radius : int
        Cells each way (an ``n`` x ``n`` interleave needs ``n // 2`` for every block of
        ``2 * (n // 2) + 1`` cells to hold a cell of each turn).
    targets : mi.Bool or bool, optional
        The cells that may be filled (those on the film).

    Returns
    -------
    res : Resolved
        The cells with the holes filled (``resampled`` marks them).
    """
    idx = dr.arange(mi.UInt32, grid.size)
    y = mi.Int32(idx // grid.width)
    x = mi.Int32(idx) - y * grid.width
    acc = dr.zeros(mi.Color3f, grid.size)
    m2 = dr.zeros(mi.Float, grid.size)
    wsum, wn, w2n = (dr.zeros(mi.Float, grid.size) for _ in range(3))
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dx == 0 and dy == 0:
                continue
            q, inside = grid.neighbour(x + dx, y + dy)
            ok = inside & dr.gather(mi.Bool, res.mask, q, inside)
            w = (1.0 - abs(dx) / (radius + 1.0)) * (1.0 - abs(dy) / (radius + 1.0))
            n = dr.gather(mi.Float, res.count, q, ok)
            acc += dr.select(ok, dr.gather(mi.Color3f, res.shading, q, ok) * w, 0.0)
            m2 += dr.select(ok, dr.gather(mi.Float, res.moment2, q, ok) * w, 0.0)
            wsum += dr.select(ok, w, 0.0)
            wn += dr.select(ok, w * n, 0.0)
            w2n += dr.select(ok, w * w * n, 0.0)
    fill = ~res.mask & targets & (wsum > 0.0)
    inv = dr.rcp(dr.select(fill, wsum, 1.0))
    return Resolved(dr.select(fill, acc * inv, res.shading), res.mask | fill,
                    dr.select(fill, wn * wn / dr.select(fill, w2n, 1.0), res.count),
                    res.resampled | fill, dr.select(fill, m2 * inv, res.moment2))


def _neighbours(cells: mi.Color3f, valid: mi.Bool, grid: Grid):
    """Each cell's eight neighbours under the grid's neighbour rule, one at a time: their
    values and whether each is inside, ``valid`` and finite."""
    _, x, y = grid.cells()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dx == 0 and dy == 0:
                continue
            q, inside = grid.neighbour(x + dx, y + dy)
            cq = dr.gather(mi.Color3f, cells, q, inside)
            yield cq, inside & dr.gather(mi.Bool, valid, q, inside) & dr.isfinite(cq.x) & \
                dr.isfinite(cq.y) & dr.isfinite(cq.z)


def stabilize(cells: mi.Color3f, valid: mi.Bool, grid: Grid, previous: mi.Color3f,
              alpha: float) -> mi.Color3f:
    """What each cell shows with ``foveal_taa``: its denoised value blended with what it
    showed in the last frame (``previous``, reprojected; non-finite where none), that clamped
    to the range of this frame's values in the cell's 3 x 3 neighbourhood, as temporal
    anti-aliasing clamps its history (Karis 2014), so that a surface newly seen or newly lit
    does not keep the old value. A cell changes by ``alpha`` of its new value a frame, so
    its noise flickers less. Linear in ``cells`` with the clamp's bounds held: the gradient
    of a loss reaches this frame's cells with weight ``alpha``, and not the last frame's
    (a history, a constant).

    Parameters
    ----------
    cells, valid : mi.Color3f, mi.Bool
        The denoised cells, and those that hold a value.
    grid : Grid
        The buffer's grid.
    previous : mi.Color3f
        Each cell's reprojected shown value of the last frame.
    alpha : float
        This frame's weight, in ``(0, 1]``.

    Returns
    -------
    shown : mi.Color3f
        The cells as shown.
    """
    here = dr.detach(cells)
    lo, hi = mi.Color3f(here), mi.Color3f(here)
    for cq, ok in _neighbours(here, valid, grid):
        lo = dr.select(ok, dr.minimum(lo, cq), lo)
        hi = dr.select(ok, dr.maximum(hi, cq), hi)
    prev = dr.detach(previous)
    use = valid & dr.isfinite(prev.x) & dr.isfinite(prev.y) & dr.isfinite(prev.z)
    prev = dr.clip(dr.select(use, prev, 0.0), lo, hi)
    return dr.select(use, dr.lerp(prev, cells, alpha), cells)


def sharpen(cells: mi.Color3f, valid: mi.Bool, grid: Grid, gain: float) -> mi.Color3f:
    """Each cell pushed away from the mean of its valid 3 x 3 neighbours by ``gain`` times
    their difference (an unsharp mask at the cells' own scale, so that its reach grows with
    eccentricity as the cells do), kept non-negative: the contrast that the cells' spacing
    and the bilinear warp take from the periphery given back (Patney et al. 2016 enhance the
    blurred periphery's contrast). Linear in ``cells`` with constant weights where it stays
    non-negative: a cell's gradient is ``1 + gain`` on itself and ``-gain / n`` on each of
    its ``n`` valid neighbours.

    Parameters
    ----------
    cells, valid : mi.Color3f, mi.Bool
        The cells' radiance, and those that hold a value.
    grid : Grid
        The buffer's grid.
    gain : float
        How far past the neighbours' mean (0: unchanged).

    Returns
    -------
    cells : mi.Color3f
        The cells sharpened (unchanged where no neighbour holds a value).
    """
    acc = dr.zeros(mi.Color3f, grid.size)
    n = dr.zeros(mi.Float, grid.size)
    for cq, ok in _neighbours(cells, valid, grid):
        acc += dr.select(ok, cq, 0.0)
        n += dr.select(ok, 1.0, 0.0)
    use = valid & (n > 0.0)
    k = dr.opaque(mi.Float, gain)
    mean = acc / dr.select(use, n, 1.0)
    return dr.select(use, dr.maximum(cells + k * (cells - mean), 0.0), cells)


def _catmull_rom(t: mi.Float) -> tuple[mi.Float, ...]:
    """The four Catmull-Rom weights of the taps at -1, 0, 1, 2 for a fraction ``t``."""
    t2 = t * t
    t3 = t2 * t
    return (0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2))


def _cubic(cells: mi.Float, grid: PolarGrid, x0: mi.Float, y0: mi.Float, fx: mi.Float,
           fy: mi.Float) -> tuple[mi.Color3f, mi.Bool]:
    """Catmull-Rom over the 4 x 4 cells around each pixel (wrapping in angle, clamping
    radially), kept non-negative; and whether all sixteen hold a value. ``cells``: their
    packet (:func:`_cell_packet`)."""
    wx, wy = _catmull_rom(fx), _catmull_rom(fy)
    acc = dr.zeros(mi.Color3f, dr.width(fx))
    every = dr.full(mi.Bool, True, dr.width(fx))
    for j in range(4):
        qy = dr.clip(mi.Int32(y0) + (j - 1), 0, grid.height - 1)
        for i in range(4):
            q, _ = grid.neighbour(_tap_x(grid, mi.Int32(x0) + (i - 1)), qy)
            v = gather4(cells, q, mi.Bool(True))
            every &= v.w > 0.0
            acc += mi.Color3f(v.x, v.y, v.z) * dr.detach(wx[i] * wy[j])
    return dr.maximum(acc, 0.0), every


def _tap_x(grid: Grid, qx: mi.Int32) -> mi.Int32:
    """A warp tap's column: as is on a wrapped axis (the grid brings it back), clamped to the
    edge on a clamped one (an even grid's, :mod:`foveated_mi.kernels.flat`), as its rows."""
    return qx if grid.wrap_x else dr.clip(qx, 0, grid.width - 1)


def _cell_packet(cells: mi.Color3f, valid: mi.Bool) -> mi.Float:
    """The cells as one packet a warp tap reads at once: the value where it is ``valid`` and
    finite (else 0), and 1 there (else 0)."""
    ok = valid & dr.isfinite(cells.x) & dr.isfinite(cells.y) & dr.isfinite(cells.z)
    c = dr.select(ok, cells, 0.0)
    return packet(c.x, c.y, c.z, dr.select(ok, 1.0, 0.0))


def warp(cells: mi.Color3f, valid: mi.Bool, grid: PolarGrid, gaze: mi.Point2f, width: int,
         height: int, guide: tuple[Surface, Surface] | None = None,
         kernel: str = "bilinear") -> mi.Color3f:
    """The buffer on the film: bilinear over the four cells around each pixel's continuous
    cell coordinates that are ``valid`` and finite (wrapping in angle, clamping radially).

    Parameters
    ----------
    cells, valid : mi.Color3f, mi.Bool
        The buffer's values, and the cells that hold one (one entry per cell of ``grid``).
    grid, gaze : PolarGrid or FlatGrid, mi.Point2f
        The buffer's grid, and the gaze's film position (pixels; an even grid ignores it,
        and clamps both ways).
    width, height : int
        The film's size.
    guide : tuple of Surface, optional
        ``(film, cells)``: the film's and the cells' G-buffers, whose edge-stopping weight
        (:func:`~foveated_mi.kernels.taps.surface_energy`, σn = 0.3 and σx = 0.1, as SVGF's)
        multiplies each cell's (a joint bilateral upsampling: a cell on another surface lends
        little; where all four do, the plain bilinear weights). None: plain bilinear.
    kernel : str, optional
        ``"cubic"``: Catmull-Rom over the 4 x 4 cells around each pixel where all of them
        hold a value (it keeps more of the cells' contrast than bilinear), the bilinear
        result elsewhere.

    Returns
    -------
    image : mi.Color3f
        One value per film pixel; 0 where no cell is valid."""
    film = Grid.film(width, height)
    idx, _, _ = film.cells()
    c = grid.coords_at(film.film_position(idx), gaze)
    u, v = c.x - 0.5, c.y - 0.5
    x0, y0 = dr.floor(u), dr.floor(v)
    fx, fy = u - x0, v - y0
    # One gather a tap: value and validity together.
    pk = _cell_packet(cells, valid)
    image = _bilinear(pk, grid, x0, y0, fx, fy,
                      None if guide is None else (guide[0].at(idx, mi.Bool(True)), guide[1]))
    if kernel == "cubic":
        sharp, every = _cubic(pk, grid, x0, y0, fx, fy)
        image = dr.select(every, sharp, image)
    return image


def _bilinear(cells: mi.Float, grid: PolarGrid, x0: mi.Float, y0: mi.Float, fx: mi.Float,
              fy: mi.Float, guide: tuple | None) -> mi.Color3f:
    """Bilinear over the four cells around each pixel that hold a value (:func:`warp`;
    ``cells``: their packet, :func:`_cell_packet`), their weights times the surfaces'
    edge-stopping weight with a ``guide`` (the pixels' surface, the cells' :class:`Surface`)."""
    n = dr.width(fx)
    acc, wsum = dr.zeros(mi.Color3f, n), dr.zeros(mi.Float, n)
    plain, psum = dr.zeros(mi.Color3f, n), dr.zeros(mi.Float, n)
    if guide is not None:
        here = guide[0]
        inv_n, inv_x = dr.opaque(mi.Float, 1.0 / 0.3 ** 2), dr.opaque(mi.Float, 1.0 / 0.1 ** 2)
    for dy, wy in ((0, 1.0 - fy), (1, fy)):
        for dx, wx in ((0, 1.0 - fx), (1, fx)):
            qy = dr.clip(mi.Int32(y0) + dy, 0, grid.height - 1)
            q, _ = grid.neighbour(_tap_x(grid, mi.Int32(x0) + dx), qy)
            v = gather4(cells, q, mi.Bool(True))
            cq = mi.Color3f(v.x, v.y, v.z)      # 0 where the cell holds no value
            w = dr.detach(wx * wy * v.w)
            if guide is not None:
                plain += cq * w
                psum += w
                there = guide[1].at(q, v.w > 0.0)
                w = w * dr.detach(dr.select(here[2] == there[2],
                                            dr.exp(-surface_energy(here, there, inv_n, inv_x)),
                                            0.0))
            acc += cq * w
            wsum += w
    if guide is not None:
        # Where no cell lies on the pixel's surface, the plain bilinear weights.
        use = wsum > 1e-4 * psum
        acc, wsum = dr.select(use, acc, plain), dr.select(use, wsum, psum)
    return dr.select(wsum > 0.0, acc / dr.select(wsum > 0.0, wsum, 1.0), 0.0)


def moving_settings(s: FovealSettings, moving: bool) -> FovealSettings:
    """The settings a frame reads: where the camera moved, the denoisers and the history's
    cap of a moving frame (``sigma_luminance_moving``, ``foveal_disc_iterations_moving``,
    ``max_history_moving``) in place of a still one's.

    Parameters
    ----------
    s : FovealSettings
        The formation's settings.
    moving : bool
        Whether the frame's camera moved since the view's last.

    Returns
    -------
    settings : FovealSettings
        ``s``, or a copy with the moving frame's denoisers and cap.
    """
    if not moving or (s.denoise_moving is None and s.disc_denoise_moving is None
                      and s.max_history_moving <= 0):
        return s
    # The motion hides what a lighter filter leaves, and a shorter history lags it less.
    return replace(s, denoise=s.denoise_moving or s.denoise,
                   disc_denoise=s.disc_denoise_moving or s.disc_denoise,
                   max_history=s.max_history_moving or s.max_history)


def form_foveal(shading: ShadingBuffer, inp: FormationInput, s: FovealSettings,
                timer: StageTimer, grad_pass: bool = False) -> Formed:
    """History resolve, denoising in the buffer, one warp (module docstring).

    Parameters
    ----------
    shading, inp, s, timer, grad_pass
        As :func:`~.film.form_film`'s, ``s`` a :class:`FovealSettings`. Returns the
        :class:`~.formation.Formed`: the image on the film, the buffers and the history."""
    s = moving_settings(s, inp.moving)
    return SPACE_FORMS[inp.space.kind](shading, inp, s, timer, grad_pass)


def _form_on_film(shading: ShadingBuffer, inp: FormationInput, s: FovealSettings,
                  timer: StageTimer, grad_pass: bool) -> Formed:
    """``foveal_space = "film"``: the history resolve on the traced pixels, each cell from
    the pixel under its centre, denoising in the buffer, one warp, the albedo multiplied back
    per pixel; the disc shows its own pixels."""
    width, height = inp.width, inp.height
    grid, d = s.grid, s.domain
    # History resolve (Fig. 4): this frame's samples blended with the reprojected history.
    resolved = _reproject.resolve(shading.value, shading.mask, inp.spp, inp.reprojection,
                                  inp.history, s.max_history, shading.moment2)
    timer.mark("reconstruct", resolved.shading, resolved.mask, resolved.count)
    # The buffer: each cell from the pixel under its centre.
    q, on = snapped_pixels(grid, inp.gaze, width, height)
    has = on & dr.gather(mi.Bool, resolved.mask, q, on)
    gb = inp.gbuffer
    if d.demodulate and inp.emission_edges is not None:
        # As in the film formation: an emitter's edge is divided by the albedo only.
        gb = gb._replace(emission=dr.select(inp.emission_edges, 0.0, gb.emission))
    # The working values: irradiance with demodulate, so that the albedo's detail comes
    # back at the film's resolution after the warp.
    res, cgb = _cells(resolved, gb, q, has)
    values = _working(res, cgb, d)
    timer.mark("reconstruct", values, res.count, cgb.normal, cgb.position)
    # Denoising in the buffer (§3.5), one warp to the film, the albedo multiplied back there.
    out = _denoise(values, res, cgb, grid, s, grad_pass, on)
    guide = (Surface.of(gb.normal, gb.position, gb.hit), Surface.of(
        cgb.normal, cgb.position, cgb.hit)) if s.upsampling == "joint" else None
    cells = sharpen(out.image, has, grid, s.contrast) if s.contrast > 0.0 else out.image
    warped = domain.to_radiance(warp(cells, has, grid, inp.gaze, width, height, guide,
                                     s.upsampling), gb, d, clamp=True)
    # The fovea disc shows its own pixels, blended into the warp across the seam.
    film = Grid.film(width, height)
    t = dr.clip((grid.fovea - dr.norm(film.film_position(film.cells()[0]) - inp.gaze))
                / SEAM, 0.0, 1.0)
    own = resolved.mask & (t > 0.0)
    mine = resolved.shading
    if s.disc == "denoised":
        # The disc's pixels through the denoiser, on their square patch of the film.
        lay = s.layout
        pixels, on = _buffer_space.patch_pixels(lay, inp.gaze, width, height)
        disc = _disc_patch(resolved, gb, pixels, on, lay.side, s, grad_pass)
        _, x, y = film.cells()
        k, in_disc = _buffer_space.disc_sample(lay, mi.Int32(x), mi.Int32(y), inp.gaze)
        own &= in_disc
        mine = dr.gather(mi.Color3f, disc, k - lay.cells, own)
    image = dr.select(own, dr.lerp(warped, mine, t), warped)
    timer.mark("post", image)
    buffers = {"traced": shading.mask, "shading": resolved.shading,
               "shading_mask": resolved.mask, "history_count": resolved.count,
               "resampled": resolved.resampled, "cells": values, "cell_mask": has,
               "filtered": out.filtered, "tonemapped": out.tonemapped, "image": image}
    history = {"mean": resolved.shading, "count": resolved.count, "moment2": resolved.moment2}
    return Formed(image, buffers, history)


def _last_shown(inp: FormationInput, c: mi.UInt32) -> mi.Color3f | None:
    """What each cell ``c`` showed in the last frame where it reads its history (non-finite
    elsewhere; ``foveal_taa``); None without a history that kept it."""
    h, rp = inp.history, inp.reprojection
    if h is None or h.shown is None:
        return None
    hit = dr.gather(mi.Bool, rp.hit, c)
    return dr.select(hit, dr.gather(mi.Color3f, h.shown, dr.gather(mi.UInt32, rp.index, c),
                                    hit), dr.nan)


def _disc_values(resolved: Resolved, inp: FormationInput, s: FovealSettings,
                 grad_pass: bool) -> tuple[mi.Color3f, mi.Bool]:
    """Each sample of the disc's square patch as the disc shows it: resolved, or through the
    denoiser on the patch (``foveal_disc = "denoised"``), and with ``foveal_taa`` blended
    with what it showed last frame; and which hold a value."""
    lay = s.layout
    patch = lay.cells + dr.arange(mi.UInt32, lay.side * lay.side)
    on = dr.gather(mi.Bool, inp.space.on, patch)
    if s.disc == "denoised":
        values = _disc_patch(resolved, inp.gbuffer, patch, on, lay.side, s, grad_pass)
    else:
        values = dr.gather(mi.Color3f, resolved.shading, patch)
    held = on & dr.gather(mi.Bool, resolved.mask, patch)
    previous = _last_shown(inp, patch) if s.taa < 1.0 else None
    if previous is not None:
        values = stabilize(values, held, Grid(lay.side, lay.side), previous, s.taa)
    return values, held


def _disc_samples(values: mi.Color3f, held: mi.Bool, inp: FormationInput, s: FovealSettings
                  ) -> tuple[mi.Bool, mi.Color3f, mi.Float]:
    """Where each film pixel shows its own disc sample (one that ``held`` a value), that
    sample's value (``values``, the patch's), and its weight across the seam."""
    lay = s.layout
    film = Grid.film(inp.width, inp.height)
    idx, x, y = film.cells()
    p = film.film_position(idx)
    t = dr.clip((lay.grid.fovea - dr.norm(p - inp.gaze)) / SEAM, 0.0, 1.0)
    k, in_disc = _buffer_space.disc_sample(lay, mi.Int32(x), mi.Int32(y), inp.gaze)
    own = in_disc & (t > 0.0)
    own &= dr.gather(mi.Bool, held, k - lay.cells, own)
    return own, dr.gather(mi.Color3f, values, k - lay.cells, own), t


def _form_on_samples(shading: ShadingBuffer, inp: FormationInput, s: FovealSettings,
                     timer: StageTimer, grad_pass: bool) -> Formed:
    """``foveal_space = "buffer"``: the history resolve on the buffer's samples, denoising
    in the buffer, the albedo multiplied back on its cells, one warp; the disc shows its own
    samples (:mod:`foveated_mi.frame.buffer_space`). Only the warp and the disc's blend run
    on the film's pixels."""
    width, height = inp.width, inp.height
    lay, d = s.layout, s.domain
    grid, nc = lay.grid, lay.cells
    pixels, on = inp.space.pixels, inp.space.on
    gb = inp.gbuffer
    # This frame's samples (the shading buffer is on them), blended with their own history;
    # with a disc rate each weighs the samples it traced.
    spp = shading.count if inp.disc_spp else inp.spp
    resolved = _reproject.resolve(shading.value, shading.mask, spp, inp.reprojection,
                                  inp.history, s.max_history, shading.moment2)
    timer.mark("reconstruct", resolved.shading, resolved.mask, resolved.count)
    # The cells: the first samples, in the working domain (irradiance with demodulate).
    c = dr.arange(mi.UInt32, nc)
    cells, res, cgb = _buffer_cells(resolved, gb, s, dr.gather(mi.Bool, on, c))
    has = res.mask
    timer.mark("reconstruct", cells, res.count, cgb.normal, cgb.position)
    # Denoising in the buffer (§3.5); each cell's albedo multiplied back before the warp:
    # there is no full-resolution albedo to take it from.
    out = _denoise(cells, res, cgb, grid, s, grad_pass, dr.gather(mi.Bool, on, c),
                   kept=None if inp.kept is None else inp.kept["cells"], keep=inp.keep)
    radiance = domain.to_radiance(out.image, cgb, d, clamp=True)
    previous = _last_shown(inp, c) if s.taa < 1.0 else None
    if previous is not None:
        # What each cell showed last frame, blended in where it reads its history.
        radiance = stabilize(radiance, has, grid, previous, s.taa)
    shown = sharpen(radiance, has, grid, s.contrast) if s.contrast > 0.0 else radiance
    warped = warp(shown, has, grid, inp.gaze, width, height, kernel=s.upsampling)
    if lay.side:
        # The disc shows its own samples, blended into the warp across the seam.
        disc, held = _disc_values(resolved, inp, s, grad_pass)
        own, mine, t = _disc_samples(disc, held, inp, s)
        image = dr.select(own, dr.lerp(warped, mine, t), warped)
    else:
        image = warped      # an even grid (``sampling_law = "flat"``): no disc
    timer.mark("post", image)
    buffers = {"traced": shading.mask, "shading": resolved.shading,
               "shading_mask": resolved.mask, "history_count": resolved.count,
               "resampled": resolved.resampled, "sample_on": on, "sample_pixel": pixels,
               "cells": cells,
               "cell_mask": has, "filtered": out.filtered, "tonemapped": out.tonemapped,
               "image": image}
    history = {"mean": resolved.shading, "count": resolved.count, "moment2": resolved.moment2}
    if s.taa < 1.0:
        # What every sample showed: the cells after the denoiser, the disc's patch as shown.
        shown = mi.Color3f(dr.detach(resolved.shading))
        dr.scatter(shown, dr.detach(radiance), c, has)
        if lay.side:
            dr.scatter(shown, dr.detach(disc), nc + dr.arange(mi.UInt32, lay.side * lay.side),
                       held)
        history["shown"] = shown
    # What the cells' denoiser derived from their G-buffer alone, for the next frames while
    # it holds (a still view).
    return Formed(image, buffers, history,
                  kept=None if out.kept is None else {"cells": out.kept})


#: Sample space (``inp.space.kind``) -> the formation on it.
SPACE_FORMS = {
    "film": _form_on_film,          # the film's pixels
    "buffer": _form_on_samples,     # the foveal buffer's samples (:mod:`.buffer_space`)
}


def _buffer_cells(resolved: Resolved, gb: GBuffer, s: FovealSettings, targets: mi.Bool
                  ) -> tuple[mi.Color3f, Resolved, GBuffer]:
    """The buffer's cells (its first samples): their working values (irradiance with
    ``demodulate``; non-finite where none), the resolved samples behind them in radiance,
    whose mean and second moment give the noise's variance in one domain, and their
    G-buffer. With ``foveal_interleave``, a cell of ``targets`` (on the film) not traced this
    frame and without history takes its neighbours' values (:func:`fill_cells`)."""
    lay = s.layout
    c = dr.arange(mi.UInt32, lay.cells)
    res, cgb = _cells(resolved, gb, c, dr.gather(mi.Bool, resolved.mask, c))
    cells = _working(res, cgb, s.domain)
    if lay.interleave > 1:
        reach = lay.interleave // 2
        cells = fill_cells(res._replace(shading=cells), lay.grid, reach, targets).shading
        res = fill_cells(res, lay.grid, reach, targets)
    return cells, res, cgb


def foveal_grids(width: int, height: int, s: FovealSettings) -> dict[str, Grid]:
    """The buffers that live on the samples (``foveal_space = "buffer"``), and their grid.

    Parameters
    ----------
    width, height : int
        The film's size (unused).
    s : FovealSettings
        The formation's settings.

    Returns
    -------
    grids : dict
        Buffer name -> the samples' one-row grid, for each of :data:`SAMPLE_BUFFERS`; empty
        in ``film`` space.
    """
    if s.space != "buffer":
        return {}
    samples = s.layout.samples_grid
    return {name: samples for name in SAMPLE_BUFFERS}


def foveal_stats(buffers: dict[str, dr.ArrayBase]) -> dict[str, Any]:
    """Film pixels, or buffer samples, that took their value from the history only, and
    those without a value (a sample off the film is none).

    Parameters
    ----------
    buffers : dict
        The formation's buffers (``resampled``, ``shading_mask`` and, on the samples,
        ``sample_on``).

    Returns
    -------
    stats : dict
        ``resampled`` and ``holes``, counts on the device; on the samples, ``reprojected``
        too (the samples on the film).
    """
    on = buffers.get("sample_on")
    if on is None:
        return film_stats(buffers)
    # ``reprojected``: the samples the history hit rate counts, as a mask (counted when the
    # stats are read, so that the frame launches no kernel for it).
    return {"resampled": dr.count(buffers["resampled"]),
            "holes": dr.count(on & ~buffers["shading_mask"]), "reprojected": on}


register_formation("foveal", form_foveal, grid=foveal_buffer_grid, stats=foveal_stats,
                   counted=("resampled", "shading_mask"), on_film=ON_FILM, grids=foveal_grids)
