r"""Headsets: the eye buffer a renderer renders, the display a viewer sees, and the lens
between them.

A pinhole eye buffer cannot have a headset panel's resolution, its field of view and its
pixels per degree at the centre all at once: the lens concentrates the panel's pixels at the
centre. Varjo XR-4's 3840 pixels over 120 degrees give a pinhole 19 pixels per degree at its
centre, not the 51 its display shows there. So a :class:`Headset` keeps three things apart:

- the **eye buffer** (:meth:`Headset.rig`): what the renderer renders, a pinhole film with
  each eye's asymmetric frustum (:class:`foveated_mi.stereo.Frustum`) and a width in pixels
  (the headset's recommended render target, or a fraction of it);
- the **display** (:class:`Display`): the panel's pixels per eye, its refresh rate, its pixels
  per degree at the centre of the lens and the photometry of a FovVideoVDP display model;
- the **lens mapping** (:meth:`Display.ppd`): the display's pixels per degree at each
  eccentricity from the lens's axis along the horizontal. Two kinds:

  - ``flat``: a flat panel seen through a pinhole, :math:`p(e) = p_0 / \cos^2 e`, rising
    toward the edges (FovVideoVDP's own display geometry: ``standard_hmd``);
  - ``lens``: a linear profile :math:`p(e) = p_0 + k e` whose integral over half the
    horizontal field of view is half the panel's width,
    :math:`p_0 E + k E^2 / 2 = W / 2`, so that :math:`k` follows from the panel, the field of
    view and the centre figure. A lens that concentrates pixels at the centre has
    :math:`k < 0`; where a source's figure is an average (Vision Pro), :math:`k > 0`.

What the viewer resolves at the centre is the smaller of the display's and the eye buffer's
pixels per degree (:meth:`Headset.viewer_ppd`): a buffer coarser than the display is
magnified, a finer one is filtered by the panel.

**The metrics' geometry.** FovVideoVDP models a flat display whose pixels per degree rise
toward its edges (as a pinhole's do). A headset study scores the eye buffer at the buffer's
own field of view (``[viewer] fov = "sensor"``): exact for the buffer's pixels, which are a
pinhole projection, but blind to the lens resampling them to the panel. Toward the edges the
panel shows fewer pixels per degree than the buffer holds (:meth:`Headset.edge_excess`), so
the metric credits peripheral detail the display cannot show.

Every figure cites its source in :data:`HEADSETS` (``sources``); where no source gives a
figure, the entry says what is assumed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .stereo import Frustum, StereoRig
from .validate import ParameterError, check_choice, check_int, check_range

#: The lens mappings :class:`Display` knows (module docstring).
LENS_KINDS = ("flat", "lens")


@dataclass(frozen=True)
class Display:
    """A headset's display for one eye: ``panel`` (width, height) pixels, ``refresh_hz``
    (None where the source gives none), ``ppd_centre`` pixels per degree at the lens's
    centre, the lens mapping ``kind`` (:data:`LENS_KINDS`) over a horizontal field of view of
    ``fov_h`` degrees, and ``photometry``, the FovVideoVDP display model of its luminance."""
    panel: tuple[int, int]
    refresh_hz: float | None
    ppd_centre: float
    fov_h: float
    kind: str = "lens"
    photometry: str = "standard_hmd"

    def __post_init__(self):
        for k, n in enumerate(("panel width", "panel height")):
            check_int(n, self.panel[k], 1, 65536)
        if self.refresh_hz is not None:
            check_range("refresh_hz", self.refresh_hz, 0.0, 1000.0, lo_open=True)
        check_range("ppd_centre", self.ppd_centre, 0.0, 1000.0, lo_open=True)
        check_range("fov_h", self.fov_h, 0.0, 180.0, lo_open=True, hi_open=True)
        check_choice("lens kind", self.kind, LENS_KINDS)
        if self.kind == "lens" and self.ppd(0.5 * self.fov_h) <= 0.0:
            raise ParameterError("ppd_centre", self.ppd_centre,
                                 f"a centre figure the panel's {self.panel[0]} pixels over "
                                 f"{self.fov_h:g} degrees allow (the profile would reach 0)")

    @property
    def slope(self) -> float:
        """:math:`k` of the ``lens`` profile, pixels per degree per degree (0 for ``flat``)."""
        if self.kind == "flat":
            return 0.0
        e = 0.5 * self.fov_h
        return 2.0 * (0.5 * self.panel[0] - self.ppd_centre * e) / (e * e)

    def ppd(self, eccentricity_deg: float) -> float:
        """The display's pixels per degree at ``eccentricity_deg`` from the lens's axis.

        Parameters
        ----------
        eccentricity_deg : float
            Degrees from the axis, along the horizontal, in [0, 90).

        Returns
        -------
        ppd : float
            Pixels per degree there.
        """
        e = check_range("eccentricity_deg", eccentricity_deg, 0.0, 90.0, hi_open=True)
        if self.kind == "flat":
            return self.ppd_centre / math.cos(math.radians(e)) ** 2
        return self.ppd_centre + self.slope * e

    def pixels_to(self, eccentricity_deg: float) -> float:
        """Panel pixels from the axis out to ``eccentricity_deg``: the integral of
        :meth:`ppd` (closed form).

        Parameters
        ----------
        eccentricity_deg : float
            Degrees from the axis, in [0, 90).

        Returns
        -------
        pixels : float
            Pixels along the horizontal.
        """
        e = check_range("eccentricity_deg", eccentricity_deg, 0.0, 90.0, hi_open=True)
        if self.kind == "flat":
            return self.ppd_centre * math.degrees(math.tan(math.radians(e)))
        return self.ppd_centre * e + 0.5 * self.slope * e * e


@dataclass(frozen=True)
class Headset:
    """A headset (module docstring): its left eye's ``frustum`` (the right one mirrors it),
    its recommended eye ``buffer`` size, its ``display``, a default ``ipd`` in metres and the
    ``sources`` of its figures (figure -> where it comes from)."""
    name: str
    title: str
    frustum: Frustum
    buffer: tuple[int, int]
    display: Display
    ipd: float = 0.063
    sources: dict = field(default_factory=dict, compare=False)

    def rig(self, width: int | None = None, ipd: float | None = None) -> StereoRig:
        """The stereo rig of this headset's eye buffers.

        Parameters
        ----------
        width : int or None, optional
            The eye buffer's width in pixels (None: the recommended ``buffer`` width); its
            height follows from the frustum with square pixels.
        ipd : float or None, optional
            The eyes' distance in scene units (None: the headset's default).

        Returns
        -------
        rig : StereoRig
            Both eyes, the right one's frustum mirroring the left one's.
        """
        width = self.buffer[0] if width is None else check_int("eye width", width, 8, 16384)
        return StereoRig(self.frustum, ipd=self.ipd if ipd is None else ipd, width=width)

    def eye_camera(self, head: dict, width: int | None = None) -> tuple[dict, tuple[int, int]]:
        """One eye at the head's pose (a single view: no IPD offset), as a camera dict and a
        film size: the left eye's frustum, its eye buffer ``width`` pixels wide.

        Parameters
        ----------
        head : dict
            A camera dict ``{origin, target, up, fov}`` (its ``fov`` is replaced).
        width : int or None, optional
            The eye buffer's width (None: the recommended one).

        Returns
        -------
        camera : dict
            ``head`` with the frustum's ``fov`` and ``principal_point``.
        size : tuple of int
            The eye buffer's ``(width, height)``.
        """
        return ({**head, "fov": self.frustum.fov_x,
                 "principal_point": list(self.frustum.principal_point)},
                self.rig(width).size("left"))

    def head_camera(self, head: dict, width: int | None = None
                    ) -> tuple[dict, tuple[int, int]]:
        """The head of both eyes (a stereo study's scene camera), as a camera dict and a film
        size: :meth:`foveated_mi.stereo.StereoRig.head`'s frustum, centred on the head's axis,
        at the eye buffers' pixels per unit tangent.

        Parameters
        ----------
        head : dict
            A camera dict ``{origin, target, up, fov}`` (its ``fov`` is replaced).
        width : int or None, optional
            The eye buffers' width (None: the recommended one).

        Returns
        -------
        camera : dict
            ``head`` with the head frustum's ``fov`` and no principal point offset.
        size : tuple of int
            The head film's ``(width, height)``.
        """
        f, size = self.rig(width).head()
        return {**head, "fov": f.fov_x, "principal_point": [0.0, 0.0]}, size

    def buffer_ppd(self, width: int | None = None) -> float:
        """The eye buffer's pixels per degree at its pinhole's centre (its optical axis).

        Parameters
        ----------
        width : int or None, optional
            The buffer's width (None: the recommended one).

        Returns
        -------
        ppd : float
            ``width / (tan(left) + tan(right))`` pixels per unit tangent, per degree.
        """
        width = self.buffer[0] if width is None else check_int("eye width", width, 8, 16384)
        tl, tr, _, _ = self.frustum.tangents
        return width / (tl + tr) * math.pi / 180.0

    def viewer_ppd(self, width: int | None = None) -> float:
        """What the viewer resolves at the centre: the smaller of the display's and the eye
        buffer's pixels per degree there (module docstring).

        Parameters
        ----------
        width : int or None, optional
            The eye buffer's width (None: the recommended one).

        Returns
        -------
        ppd : float
            Pixels per degree.
        """
        return min(self.display.ppd_centre, self.buffer_ppd(width))

    def edge_excess(self, width: int | None = None) -> float:
        """How many times more pixels per degree the eye buffer holds than the display shows,
        at the frustum's wider horizontal edge (above 1: the metric's flat geometry credits
        detail the panel cannot show there).

        Parameters
        ----------
        width : int or None, optional
            The eye buffer's width (None: the recommended one).

        Returns
        -------
        ratio : float
            Buffer ppd over display ppd at that edge.
        """
        edge = max(self.frustum.left, self.frustum.right)
        buffer = self.buffer_ppd(width) / math.cos(math.radians(edge)) ** 2
        return buffer / self.display.ppd(min(edge, 89.0))


def _quest3() -> Headset:
    return Headset(
        "quest3", "Meta Quest 3", Frustum(54.00, 40.00, 43.98, 54.27), (2064, 2240),
        Display((2064, 2208), 90.0, 25.0, 94.0, "lens"),
        sources={"frustum": "hmdgdb, hmd_cfgs/MetaQuest3_Native_R72.md (Oculus runtime "
                            "1.89, left eye head FOV)",
                 "buffer": "hmdgdb, same file: recommended render target size",
                 "panel": "Meta Quest 3 specifications; Road to VR (2,064 x 2,208 per eye)",
                 "refresh_hz": "Meta Quest 3 specifications (72, 90 and 120 Hz; 90 here)",
                 "ppd_centre": "Meta Quest 3 announcement (25 pixels per degree)",
                 "photometry": "assumed: FovVideoVDP's standard_hmd"})


def _vision_pro() -> Headset:
    return Headset(
        "vision_pro", "Apple Vision Pro", Frustum(50.0, 50.0, 46.17, 46.17), (3660, 3200),
        Display((3660, 3200), 90.0, 34.0, 100.0, "lens"),
        sources={"panel": "iFixit teardown (3,660 x 3,200 per eye)",
                 "ppd_centre": "iFixit teardown (about 34 pixels per degree over about 100 "
                               "degrees: an average, so the profile rises toward the edges)",
                 "frustum": "assumed: no measured frustum is published; 100 degrees across "
                            "(iFixit), symmetric; up and down as a pinhole with the panel's "
                            "aspect gives (tan 46.17 = tan 50 x 3200 / 3660)",
                 "buffer": "assumed: the panel's size (no published render target)",                 "refresh_hz": "Apple Vision Pro specifications (90, 96 and 100 Hz; 90 here)",
                 "photometry": "assumed: FovVideoVDP's standard_hmd"})


def _varjo_xr4() -> Headset:
    return Headset(
        "varjo_xr4", "Varjo XR-4", Frustum(60.0, 60.0, 52.5, 52.5), (3840, 3744),
        Display((3840, 3744), 90.0, 51.0, 120.0, "lens"),
        sources={"panel": "Varjo XR-4 specifications (3840 x 3744 per eye)",
                 "ppd_centre": "Varjo XR-4 specifications (51 pixels per degree)",
                 "frustum": "Varjo XR-4 specifications (120 x 105 degrees), taken as each "
                            "eye's and symmetric (no measured frustum is published)",
                 "buffer": "assumed: the panel's size",
                 "refresh_hz": "Varjo XR-4 specifications (90 Hz)",
                 "photometry": "assumed: FovVideoVDP's standard_hmd"})


def _vive_pro() -> Headset:
    return Headset(
        "htc_vive_pro", "HTC Vive Pro", Frustum(53.57, 45.27, 53.49, 54.33), (2468, 2740),
        Display((1440, 1600), 90.0, 13.153, 98.84, "lens", photometry="htc_vive_pro"),
        sources={"frustum": "hmdgdb, hmd_cfgs/VivePro_Native_R90.md (OpenVR 2.9.6, left "
                            "eye head FOV)",
                 "buffer": "hmdgdb, same file: OpenVR's recommended render target size",
                 "panel": "FovVideoVDP display_models.json, htc_vive_pro (1440 x 1600)",
                 "refresh_hz": "HTC Vive Pro specifications (90 Hz)",
                 "ppd_centre": "FovVideoVDP's geometry of htc_vive_pro (1440 x 1600, 110 "
                               "degrees diagonal: 13.15 pixels per degree at the centre)",
                 "photometry": "FovVideoVDP display_models.json, htc_vive_pro"})


def _standard_hmd() -> Headset:
    # FovVideoVDP's flat geometry of 1440 x 1600 pixels over 110 degrees diagonally: 87.39 x
    # 93.42 degrees, 13.15 pixels per degree at the centre.
    return Headset(
        "standard_hmd", "FovVideoVDP standard_hmd", Frustum(43.693, 43.693, 46.710, 46.710),
        (1440, 1600), Display((1440, 1600), None, 13.153, 87.386, "flat"),
        sources={"all": "FovVideoVDP display_models.json, standard_hmd (1440 x 1600, 110 "
                        "degrees diagonal), seen through FovVideoVDP's flat display geometry"})


#: Headset name -> its model (module docstring; each figure's source in ``sources``).
HEADSETS: dict[str, Headset] = {h.name: h for h in (_standard_hmd(), _vive_pro(), _quest3(),
                                                    _vision_pro(), _varjo_xr4())}


def headset(name: str, key: str = "headset") -> Headset:
    """The headset called ``name`` (:data:`HEADSETS`).

    Parameters
    ----------
    name : str
        One of :data:`HEADSETS`.
    key : str, optional
        What the error names (``--headset`` on the command line).

    Returns
    -------
    headset : Headset
        Its model.
    """
    return HEADSETS[check_choice(key, name, HEADSETS)]


def headset_table(width: int | None = None) -> str:
    """The headsets as a Markdown table: what each renders, what its display shows and what
    the viewer resolves (``foveated-mi headsets``).

    Parameters
    ----------
    width : int or None, optional
        The eye buffer's width for the buffer's columns (None: each one's render target).

    Returns
    -------
    table : str
        One row per headset, then each figure's source.
    """
    rows = ["| headset | eye buffer | frustum L / R / U / D (deg) | panel | Hz "
            "| display ppd, centre | display ppd, wider edge | buffer ppd, centre | viewer ppd "
            "| buffer / display at the edge |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for h in HEADSETS.values():
        d, f = h.display, h.frustum
        w, ht = h.rig(width).size("left")
        edge = max(f.left, f.right)
        rows.append(
            f"| `{h.name}` | {w}x{ht} | {f.left:g} / {f.right:g} / {f.up:g} / {f.down:g} "
            f"| {d.panel[0]}x{d.panel[1]} | {'-' if d.refresh_hz is None else f'{d.refresh_hz:g}'} "
            f"| {d.ppd_centre:.2f} | {d.ppd(min(edge, 89.0)):.2f} | {h.buffer_ppd(width):.2f} "
            f"| {h.viewer_ppd(width):.2f} | {h.edge_excess(width):.2f} |")
    notes = [f"- `{h.name}` ({h.title}): " + "; ".join(f"{k}: {v}" for k, v in h.sources.items())
             for h in HEADSETS.values()]
    return "\n".join(rows + [""] + notes) + "\n"
