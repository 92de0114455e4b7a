"""Two eyes from one head pose: a stereo rig, each eye's off-axis frustum and sensor, and the
gaze of each eye from one fixation point.

The scene's own sensor is the *head* (the cyclopean eye between the two): its pose moves the
rig, and a gaze on its film is the cyclopean gaze. :class:`StereoRig` places the eyes
``ipd / 2`` to either side along the head's right axis, with parallel axes (a headset's eyes
are not turned inward), and gives each its own frustum: the angles from its axis to the left,
right, top and bottom edges of its eye buffer, asymmetric as a headset's are (the nasal side
narrower). An eye's sensor is Mitsuba's ``perspective`` with its principal point shifted off
the film's centre, so that its corner rays make exactly those angles.

Both eyes look at one point (:func:`fixation`): where the head's gaze ray meets a surface,
or, on a miss, a set distance along it (2 m by default). Each eye's gaze is that point on its
own film (:func:`eye_gaze`), so the two foveae fall on the same surface.

:class:`Stereo` renders both eyes of one head pose with one call. Each eye is a view of the
integrator of its own (:class:`foveated_mi.frame.view.Views`): its own gaze, plan and history,
as two integrators would keep them (unless the second reuses the first one's samples,
below). A cut resets both histories (:meth:`Stereo.cut`). Under a frame budget (``frame_ms``)
the two eyes are one frame: they share the budget and render at one configuration
(:meth:`foveated_mi.budget.FrameBudget.together`).

**Reuse between the eyes** (``reuse=True``, the default; a formation on the foveal buffer's
samples, as the ``vr`` preset's). The first eye renders its frame as it would alone. The
second reprojects the first eye's samples of that frame into its own, by its history's rules
(the plane test, exclusive reads), reads them only where a shadow ray says the first eye saw
the very point (:func:`foveated_mi.frame.eye_reuse.partner_map`), and traces the rest:
what the first eye did not see (the crescents, :func:`crescent`), the sky, and surfaces whose
BSDF has a glossy or delta lobe, whose radiance differs between the eyes. With
``reuse="periphery"`` it traces its own disc too; otherwise a disc pixel reuses the first
eye's value only of a point landing within an eighth of a pixel of its centre
(:data:`foveated_mi.frame.eye_reuse.DISC_REACH`), where it stands for that pixel, and
traces the rest (measured: ``docs/results.md#two-eyes-in-a-headset``).
Where a sample is reused, both eyes show the same estimate: their noise there is shared, not
independent, which a per-eye metric cannot tell from independent noise (neither sees
binocular rivalry). Reused values are constants to a gradient pass, as history is. Without
reuse, or on the film's pixels, the eyes share nothing.

Scene units are taken to be metres (the IPD's default, 63 mm, and the 2 m fixation).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import mitsuba as mi
import numpy as np

from .validate import ParameterError, check_choice, check_int, check_point2, check_range

#: The eyes, in the order :class:`Stereo` renders them by default.
EYES = ("left", "right")

#: What the second eye may reuse of the first eye's samples (:class:`Stereo`'s ``reuse``):
#: all it can, the cells outside its disc only, or nothing.
REUSE = (True, "periphery", False)


def check_reuse(name: str, value) -> bool | str:
    """``value`` if it is one of :data:`REUSE`, else one line naming ``name``.

    Parameters
    ----------
    name : str
        The input's name in the message.
    value : object
        The value given.

    Returns
    -------
    reuse : bool or str
        ``value``.
    """
    if isinstance(value, bool) or value == "periphery":
        return value
    raise ParameterError(name, value, "true, false or 'periphery'")


@dataclass(frozen=True)
class Frustum:
    """One eye's field of view: the angles in degrees from its axis to the left, right, top
    and bottom edges of its eye buffer, each in (0, 90)."""
    left: float
    right: float
    up: float
    down: float

    def __post_init__(self):
        for side in ("left", "right", "up", "down"):
            check_range(f"frustum {side}", getattr(self, side), 0.0, 90.0, lo_open=True,
                        hi_open=True)

    @property
    def tangents(self) -> tuple[float, float, float, float]:
        """The tangents of (left, right, up, down)."""
        return tuple(math.tan(math.radians(a))
                     for a in (self.left, self.right, self.up, self.down))

    @property
    def fov_x(self) -> float:
        """The whole horizontal field of view in degrees, as a ``perspective`` sensor's ``fov``
        (``fov_axis = "x"``) with :attr:`principal_point` spans it."""
        tl, tr, _, _ = self.tangents
        return math.degrees(2.0 * math.atan(0.5 * (tl + tr)))

    @property
    def principal_point(self) -> tuple[float, float]:
        """The optical axis's offset from the film's centre, in film widths and heights
        (Mitsuba's ``principal_point_offset_x``/``_y``): Mitsuba shifts the frustum by twice
        the offset times the half-extent, so these put the corner rays at the frustum's
        angles."""
        tl, tr, tu, td = self.tangents
        return (tr - tl) / (2.0 * (tl + tr)), (td - tu) / (2.0 * (tu + td))

    @property
    def axis(self) -> tuple[float, float]:
        """Where the optical axis meets the eye buffer, as a normalised film position
        (x from the left edge, y from the top): ``tan(left) / (tan(left) + tan(right))``
        across, ``tan(up) / (tan(up) + tan(down))`` down."""
        tl, tr, tu, td = self.tangents
        return tl / (tl + tr), tu / (tu + td)

    def mirrored(self) -> Frustum:
        """The other eye's frustum: left and right swapped."""
        return Frustum(self.right, self.left, self.up, self.down)


@dataclass(frozen=True)
class StereoRig:
    """Two eyes ``ipd`` apart (scene units; 63 mm by default), each with its own frustum
    (``right`` defaults to ``left`` mirrored) and an eye buffer ``width`` pixels wide, as
    many high as its frustum's aspect asks for with square pixels."""
    left: Frustum = Frustum(50.0, 40.0, 45.0, 50.0)
    right: Frustum | None = None
    ipd: float = 0.063
    width: int = 640

    def __post_init__(self):
        check_range("ipd", self.ipd, 0.0, lo_open=True)
        check_int("eye buffer width", self.width, 8, 16384)
        for name in ("left", "right"):
            f = getattr(self, name)
            if f is not None and not isinstance(f, Frustum):
                raise ParameterError(f"{name} frustum", f, "a Frustum(left, right, up, down)")
        if self.right is None:
            object.__setattr__(self, "right", self.left.mirrored())

    def frustum(self, eye: str) -> Frustum:
        """The frustum of ``eye`` (``'left'`` or ``'right'``).

        Parameters
        ----------
        eye : str
            ``'left'`` or ``'right'``.

        Returns
        -------
        frustum : Frustum
            Its angles.
        """
        return self.left if _eye(eye) == "left" else self.right

    def size(self, eye: str) -> tuple[int, int]:
        """The eye buffer's size: ``width`` across, the height its frustum's aspect gives.

        Parameters
        ----------
        eye : str
            Whose buffer: one of :data:`EYES`.

        Returns
        -------
        size : tuple of int
            ``(width, height)`` in pixels.
        """
        tl, tr, tu, td = self.frustum(eye).tangents
        return self.width, max(1, round(self.width * (tu + td) / (tl + tr)))

    def head(self) -> tuple[Frustum, tuple[int, int]]:
        """The head's (cyclopean) frustum and film: centred on the head's axis, each side as
        wide as the wider eye's, at the eyes' pixels per unit tangent. A head's gaze at its
        film's centre then looks straight ahead, and the eyes' gazes mirror each other; on
        the left eye's off-axis frustum it would look 15° to the left under Quest 3's, and
        the right eye would see its periphery out to 69°.

        Returns
        -------
        frustum : Frustum
            Symmetric: ``left == right``, ``up == down``.
        size : tuple of int
            Its film's ``(width, height)`` in pixels.
        """
        a, b = self.frustum("left"), self.frustum("right")
        across = max(a.left, a.right, b.left, b.right)
        vertical = max(a.up, a.down, b.up, b.down)
        f = Frustum(across, across, vertical, vertical)
        tl, tr, _, _ = a.tangents
        tx, _, ty, _ = f.tangents
        per_tangent = self.width / (tl + tr)
        return f, (max(1, round(2.0 * tx * per_tangent)), max(1, round(2.0 * ty * per_tangent)))

    def realised(self, eye: str) -> Frustum:
        """The frustum the eye's sensor has: its left and right angles exactly, its up and
        down angles within half a pixel of the frustum's (the eye buffer's height is a whole
        number of square pixels, so its vertical extent scales by the rounded height over the
        exact one).

        Parameters
        ----------
        eye : str
            The eye whose realised angles are returned, ``'left'`` or ``'right'``.

        Returns
        -------
        frustum : Frustum
            The angles of the sensor's corner rays.
        """
        f = self.frustum(eye)
        tl, tr, tu, td = f.tangents
        width, height = self.size(eye)
        k = (tl + tr) * height / (width * (tu + td))
        return Frustum(f.left, f.right, math.degrees(math.atan(k * tu)),
                       math.degrees(math.atan(k * td)))

    def eye_to_world(self, head: mi.ScalarTransform4f, eye: str) -> mi.ScalarTransform4f:
        """The pose of ``eye``: the head's, moved ``ipd / 2`` along the head's right axis (its
        local -x: a Mitsuba camera's local +x points to its left), axes parallel.

        Parameters
        ----------
        head : mi.ScalarTransform4f
            The head's to-world transform (the scene sensor's).
        eye : str
            Which eye to place (``'left'``: ``+ipd/2`` along the head's local x).

        Returns
        -------
        to_world : mi.ScalarTransform4f
            The eye's to-world transform.
        """
        side = 0.5 * self.ipd if _eye(eye) == "left" else -0.5 * self.ipd
        return head @ mi.ScalarTransform4f().translate([side, 0.0, 0.0])

    def sensor(self, head: mi.ScalarTransform4f, eye: str, *, spp: int = 1,
               rfilter=None) -> mi.Sensor:
        """A perspective sensor for ``eye``: its pose, its off-axis frustum, its eye buffer.

        Parameters
        ----------
        head : mi.ScalarTransform4f
            The head's to-world transform.
        eye : str
            The eye the sensor renders.
        spp : int, optional
            Its sampler's samples per pixel.
        rfilter : dict or mi.ReconstructionFilter, optional
            Its film's reconstruction filter, as a plugin dict or an instance (Mitsuba's
            default, ``gaussian``, when None).

        Returns
        -------
        sensor : mi.Sensor
            A ``perspective`` sensor whose corner rays make the angles of :meth:`realised`.
        """
        frustum = self.frustum(eye)
        width, height = self.size(eye)
        film = {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb"}
        if rfilter is not None:
            film["rfilter"] = rfilter
        ppx, ppy = frustum.principal_point
        return mi.load_dict({
            "type": "perspective", "fov_axis": "x", "fov": frustum.fov_x,
            "principal_point_offset_x": ppx, "principal_point_offset_y": ppy,
            "to_world": self.eye_to_world(head, eye),
            "sampler": {"type": "independent", "sample_count": int(spp)},
            "film": film})


def _other(eye: str) -> str:
    return "right" if eye == "left" else "left"


def _eye(eye: str) -> str:
    return check_choice("eye", eye, EYES)


def _to_world(sensor: mi.Sensor) -> np.ndarray:
    """A sensor's to-world matrix, (4, 4) float64 (as :func:`~.scenes.camera_of` reads it)."""
    return np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4)


def fixation(scene: mi.Scene, head: mi.Sensor, gaze, distance: float = 2.0
             ) -> tuple[np.ndarray, bool]:
    """The point both eyes look at: where the head's gaze ray meets a surface, else
    ``distance`` along it.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    head : mi.Sensor
        The head's sensor (the cyclopean eye).
    gaze : tuple of float
        The gaze on the head's film, normalised (origin top-left).
    distance : float, optional
        Where the point lies on a miss (the sky), in scene units.

    Returns
    -------
    point : numpy.ndarray
        The fixation point, world space, shape (3,).
    hit : bool
        Whether the gaze ray met a surface.
    """
    gaze = check_point2("gaze", gaze)
    check_range("fixation distance", distance, 0.0, lo_open=True)
    ray, _ = head.sample_ray(0.0, 0.5, mi.Point2f(*gaze), mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    d = np.array([ray.d.x[0], ray.d.y[0], ray.d.z[0]], dtype=np.float64)
    if bool(si.is_valid()[0]):
        return np.array([si.p.x[0], si.p.y[0], si.p.z[0]], dtype=np.float64), True
    # The distance counts from the eye's centre (the ray starts on the near clip plane).
    centre = _to_world(head)[:3, 3]
    return centre + float(distance) * d, False


def eye_gaze(rig: StereoRig, head: mi.ScalarTransform4f, eye: str, point) -> tuple[float, float]:
    """Where ``point`` lies on the film of ``eye``: its gaze, normalised (origin top-left;
    outside [0, 1] where the point is outside the eye's frustum).

    Parameters
    ----------
    rig : StereoRig
        The rig.
    head : mi.ScalarTransform4f
        The head's to-world transform.
    eye : str
        The eye whose film the point is projected on.
    point : array_like
        A world-space point in front of the eye.

    Returns
    -------
    gaze : tuple of float
        Its normalised film position.
    """
    to_local = rig.eye_to_world(head, eye).inverse()
    p = to_local @ mi.ScalarPoint3f(*[float(v) for v in point])
    if not p.z > 0.0:
        raise ParameterError("fixation point", tuple(point), f"a point in front of the {eye} eye")
    tl, tr, tu, td = rig.frustum(eye).tangents
    # Local +x is the camera's left and +y its up: the film's u grows to the right, v down.
    return (float((tl - p.x / p.z) / (tl + tr)), float((tu - p.y / p.z) / (tu + td)))


class StereoFrame(NamedTuple):
    """Both eyes' images of one head pose."""
    left: Any                      #: the left eye's image, (H, W, 3)
    right: Any                     #: the right eye's image
    gazes: tuple[tuple[float, float], tuple[float, float]]   #: each eye's gaze (normalised)
    fixation: np.ndarray | None    #: the point both eyes look at (None: given per eye)
    hit: bool                      #: whether the head's gaze ray met a surface


class EyeSensors:
    """Each eye's sensor of a rig, following the head (the scene's first sensor): built once,
    moved by :meth:`follow` only when the head has moved (a move is what a frame's history
    sees as a camera move).

    Parameters
    ----------
    scene : mi.Scene
        The scene; its first sensor is the head.
    rig : StereoRig
        The eyes.
    """

    def __init__(self, scene: mi.Scene, rig: StereoRig):
        self.scene, self.rig = scene, rig
        self.head = scene.sensors()[0]
        spp = self.head.sampler().sample_count()
        pose = self.head_pose()
        # The eyes' films filter as the head's does (the scene's film filter, not Mitsuba's
        # default Gaussian).
        rfilter = self.head.film().rfilter()
        self.sensors = {eye: rig.sensor(pose, eye, spp=spp, rfilter=rfilter) for eye in EYES}
        self._poses = {eye: np.array(rig.eye_to_world(pose, eye).matrix, dtype=np.float64)
                       for eye in EYES}

    def __getitem__(self, eye: str) -> mi.Sensor:
        return self.sensors[_eye(eye)]

    def head_pose(self) -> mi.ScalarTransform4f:
        """The head's to-world transform, as the scene's sensor has it now."""
        return mi.ScalarTransform4f(_to_world(self.head))

    def follow(self) -> mi.ScalarTransform4f:
        """Move each eye to the head's current pose (only an eye whose pose changed).

        Returns
        -------
        head : mi.ScalarTransform4f
            The head's pose.
        """
        pose = self.head_pose()
        for eye in EYES:
            to_world = self.rig.eye_to_world(pose, eye)
            matrix = np.array(to_world.matrix, dtype=np.float64)
            if not np.array_equal(self._poses[eye], matrix):
                params = mi.traverse(self.sensors[eye])
                params["to_world"] = to_world
                params.update()
                self._poses[eye] = matrix
        return pose

    def gazes(self, gaze, distance: float = 2.0):
        """Each eye's gaze at the head's current pose: both fixate where the head's ``gaze``
        meets the scene (:func:`fixation`); a point outside an eye's frustum puts its gaze at
        the nearest edge of its film.

        Parameters
        ----------
        gaze : tuple of float
            The head's gaze, normalised on its film.
        distance : float, optional
            Where the point lies when the gaze ray meets nothing.

        Returns
        -------
        gazes : tuple of tuple of float
            The left and right eyes' gazes, normalised.
        point : numpy.ndarray
            The fixation point.
        hit : bool
            Whether the gaze ray met a surface.
        """
        pose = self.head_pose()
        point, hit = fixation(self.scene, self.head, gaze, distance)
        out = []
        for eye in EYES:
            g = eye_gaze(self.rig, pose, eye, point)
            out.append((min(max(g[0], 0.0), 1.0), min(max(g[1], 0.0), 1.0)))
        return tuple(out), point, hit


class Stereo:
    """Renders both eyes of a rig with one foveated integrator, each eye a view of its own
    (module docstring).

    Parameters
    ----------
    scene : mi.Scene
        The scene; its first sensor is the head.
    integrator : FoveatedIntegrator
        The integrator that renders both eyes.
    rig : StereoRig, optional
        The eyes (default: :class:`StereoRig`'s).
    views : tuple of int, optional
        The integrator's views the eyes use (default: 1 and 2; view 0 stays the scene's
        sensor's).
    fixation_distance : float, optional
        Where the eyes converge when the head's gaze ray meets nothing.
    reuse : bool or str, optional
        The second eye reuses the first eye's samples where it sees the same diffuse surface
        (module docstring): True (a disc pixel only where the first eye's point lands within
        an eighth of a pixel of its centre), or ``"periphery"`` (its disc traced), or False.
    first : str, optional
        The eye rendered first, whose samples the other reuses: ``"left"`` or ``"right"``.
    """

    def __init__(self, scene: mi.Scene, integrator, rig: StereoRig | None = None,
                 views: tuple[int, int] = (1, 2), fixation_distance: float = 2.0,
                 reuse: bool = True, first: str = "left"):
        self.scene, self.integrator = scene, integrator
        self.rig = rig if rig is not None else StereoRig()
        if len(views) != 2 or views[0] == views[1]:
            raise ParameterError("views", views, "two different view indices")
        self.fixation_distance = check_range("fixation distance", fixation_distance, 0.0,
                                             lo_open=True)
        self.first = check_choice("first eye", first, EYES)
        self.reuse = check_reuse("reuse", reuse)
        self.eyes = EyeSensors(scene, self.rig)
        self.head, self.sensors = self.eyes.head, self.eyes.sensors
        self.views = {eye: integrator.views.bind(self.sensors[eye], v)
                      for eye, v in zip(EYES, views)}
        self.order = (self.first, _other(self.first))
        second = self.views[self.order[1]].planner
        second.partner = self.views[self.first].planner if reuse else None
        second.partner_disc = reuse is True
        self.views[self.first].planner.partner = None
        # One frame to a frame budget (frame_ms): both eyes at one rung, their time summed.
        self._budget = integrator._budget.value
        self._budget.together(tuple(self.views[eye].index for eye in self.order))

    def head_pose(self) -> mi.ScalarTransform4f:
        """The head's to-world transform, as the scene's sensor has it now."""
        return self.eyes.head_pose()

    def cut(self) -> None:
        """A camera cut: both eyes' histories start again, and the frame budget's model of
        the pair."""
        for view in self.views.values():
            view.reset()
        self._budget.reset([view.index for view in self.views.values()])

    def render(self, gaze=(0.5, 0.5), *, seed: int = 0, spp: int = 0,
               eye_gazes=None) -> StereoFrame:
        """Both eyes at the head's current pose, looking at the head's gaze (or each at its
        own).

        Parameters
        ----------
        gaze : tuple of float, optional
            The gaze on the head's film, normalised (origin top-left).
        eye_gazes : pair of tuple of float, optional
            Each eye's gaze on its own film (a binocular eye tracker's): ``gaze`` and the
            fixation are then not used (the frame's ``fixation`` is None).
        seed : int, optional
            The frame's seed (the right eye's is ``seed`` + 1, so the eyes' noise is
            independent).
        spp : int, optional
            Samples per pixel (0: the head sensor's).

        Returns
        -------
        frame : StereoFrame
            Both images, each eye's gaze and the fixation point.
        """
        # Only a moved head updates the eyes: an update is a camera move to the frame.
        self.eyes.follow()
        if eye_gazes is None:
            gazes, point, hit = self.eyes.gazes(gaze, self.fixation_distance)
        else:
            gazes = tuple(check_point2(f"eye_gazes[{k}]", g) for k, g in enumerate(eye_gazes))
            if len(gazes) != 2:
                raise ParameterError("eye_gazes", eye_gazes, "two gazes, left and right")
            point, hit = None, False
        images = {}
        for eye in self.order:
            k = EYES.index(eye)
            self.views[eye].gaze = gazes[k]
            images[eye] = mi.render(self.scene, integrator=self.integrator,
                                    sensor=self.sensors[eye], seed=seed + k, spp=spp)
        return StereoFrame(images["left"], images["right"], gazes, point, hit)


def crescent(eyes: EyeSensors, eye: str = "right") -> np.ndarray:
    """What ``eye`` sees that the other eye does not: its pixels whose surface point (the
    pixel centre's primary hit) lies outside the other eye's frustum or behind something
    from the other eye. No sample of the other eye can stand for these (a reuse between the
    eyes would have to trace them); the sky, seen by both, is not part of it.

    Parameters
    ----------
    eyes : EyeSensors
        Both eyes, at the head's current pose (:meth:`EyeSensors.follow` first).
    eye : str, optional
        The eye whose pixels are classified.

    Returns
    -------
    mask : numpy.ndarray
        (H, W) bool, True where only ``eye`` sees the point.
    """
    from .kernels import film_size, pixel_coords, primary_rays
    other_eye = _other(_eye(eye))
    sensor, other = eyes[eye], eyes[other_eye]
    width, height = film_size(sensor)
    _, x, y = pixel_coords(width, height)
    si = eyes.scene.ray_intersect(primary_rays(sensor, x, y, width, height))
    hit = si.is_valid()
    # The other eye's view of each point: inside its frustum (its film's [0, 1]^2 through the
    # sensor's own inverse projection) and not occluded on the way (a shadow ray).
    to_local = np.linalg.inv(_to_world(other))
    p = np.stack([np.asarray(si.p.x), np.asarray(si.p.y), np.asarray(si.p.z)], axis=1)
    local = p @ to_local[:3, :3].T + to_local[:3, 3]
    tl, tr, tu, td = eyes.rig.realised(other_eye).tangents
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (tl - local[:, 0] / local[:, 2]) / (tl + tr)
        v = (tu - local[:, 1] / local[:, 2]) / (tu + td)
    inside = (local[:, 2] > 0) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
    origin = _to_world(other)[:3, 3]
    d = p - origin
    dist = np.linalg.norm(d, axis=1)
    ok = np.isfinite(dist) & (dist > 0)
    d = np.where(ok[:, None], d / np.where(ok, dist, 1.0)[:, None], [0.0, 0.0, 1.0])
    # Stop short of the point by a relative margin (float32 positions).
    tmax = np.where(ok, dist * (1.0 - 1e-4), 0.0)
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(np.full(len(dist), c)) for c in origin]),
                   mi.Vector3f(*[mi.Float(d[:, k]) for k in range(3)]))
    ray.maxt = mi.Float(tmax)
    blocked = np.asarray(eyes.scene.ray_test(ray))
    seen = inside & ok & ~blocked
    return (np.asarray(hit) & ~seen).reshape(height, width)


def frustum_of(sensor: mi.Sensor) -> Frustum:
    """The frustum of a pinhole ``sensor``: the angles of the rays through the middles of its
    film's edges, measured in its own frame (a stereo rig whose eyes see what the head sees).

    Parameters
    ----------
    sensor : mi.Sensor
        The pinhole sensor to measure, in any pose (a ``perspective`` one).

    Returns
    -------
    frustum : Frustum
        Its left, right, up and down angles in degrees.
    """
    to_local = np.linalg.inv(_to_world(sensor)[:3, :3])
    angles = []
    for (u, v), (axis, sign) in zip(((0.0, 0.5), (1.0, 0.5), (0.5, 0.0), (0.5, 1.0)),
                                    ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(u, v), mi.Point2f(0.5, 0.5))
        d = to_local @ np.array([ray.d.x[0], ray.d.y[0], ray.d.z[0]], dtype=np.float64)
        angles.append(math.degrees(math.atan2(sign * d[axis], d[2])))
    return Frustum(*angles)


def write_stereo(path: str, frame: StereoFrame, *, exposure: float = 0.0,
                 tonemap: str | None = None) -> str:
    """Both eyes into one OpenEXR file (layers ``left`` and ``right``, each eye's gaze in its
    header) and a PNG preview next to it, the eyes side by side.

    Parameters
    ----------
    path : str
        The EXR file (``.exr``).
    frame : StereoFrame
        What :meth:`Stereo.render` returned.
    exposure : float, optional
        The preview's exposure, in stops.
    tonemap : str or None, optional
        The preview's tone curve.

    Returns
    -------
    png : str
        The preview's path.
    """
    import json
    import os
    from .io import write_exr, write_png
    left, right = (np.asarray(frame.left, dtype=np.float32),
                   np.asarray(frame.right, dtype=np.float32))
    if left.shape != right.shape:
        raise ParameterError("stereo frame", (left.shape, right.shape),
                             "two eye buffers of one size (a rig whose frusta mirror each other)")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    write_exr(path, {"left": left, "right": right},
              attrs={"foveated_mi_stereo": json.dumps({"gazes": frame.gazes,
                                                       "fixation": None if frame.fixation is None
                                                       else list(map(float, frame.fixation)),
                                                       "hit": bool(frame.hit)})})
    png = os.path.splitext(path)[0] + ".png"
    write_png(png, np.concatenate([left, right], axis=1), exposure=exposure, tonemap=tonemap)
    return png
