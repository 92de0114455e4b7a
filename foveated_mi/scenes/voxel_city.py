"""``voxel-city``: a Minecraft-style city of unit voxels on a ``size`` x ``size`` grid.

Streets every :data:`BLOCK_PITCH` cells, sidewalks, parks with voxel trees and buildings of
random heights (taller downtown, some with set-back towers). The city is a height field
``h[i, j]`` (in voxels) meshed like a voxel game: one top quad per cell plus one side quad for
every exposed voxel face. The triangle count is therefore exactly
(see :func:`voxel_city_triangle_count`)

    T = 2 * (size**2 + sum_{cells c, 4 directions d} max(h[c] - h[c + d], 0)) + 2,

with ``h = 0`` outside the grid; the final 2 are the ground plane (a rectangle). The grid
always spans :data:`CITY_EXTENT` world units and the peak height is ``max(12, 0.45 size)``
voxels, so the city keeps its proportions at any ``size`` and ``T`` grows roughly as
``size**3`` (seed 0)::

    size      32      64       96    128 (default)       200        256
    T      6,554  43,598  151,994        334,478   1,199,958  2,446,742

Build times: ``docs/results.md#scene-build-time``.

The whole city is one :class:`mi.Mesh` with a per-face colour attribute, built with NumPy at
scene-build time (not in the render path). A sky (a gradient environment map, ``envmap=False``
drops it) and a sun (directional emitter) light it.
"""
from __future__ import annotations

import math

import numpy as np
import mitsuba as mi

from ..validate import ParameterError, check_int

__all__ = ["BLOCK_PITCH", "CITY_EXTENT", "voxel_city_heights", "voxel_city_triangle_count"]

#: Cells from one street to the next: 2 street cells, then an 8-cell block whose outer
#: ring is sidewalk and whose 6 x 6 interior holds up to four lots.
BLOCK_PITCH = 10
CITY_EXTENT = 80.0   # world units covered by the grid along x and z, whatever its size

# Cell kinds (index into _KIND_COLOURS for everything that is not a building).
_ASPHALT, _SIDEWALK, _GRASS, _TREE, _BUILDING = 0, 1, 2, 3, 4
_KIND_COLOURS = np.array([[0.08, 0.08, 0.09], [0.45, 0.44, 0.42], [0.18, 0.38, 0.10],
                          [0.06, 0.26, 0.05]], dtype=np.float32)
_FACADES = np.array([[0.62, 0.58, 0.52], [0.55, 0.28, 0.20], [0.75, 0.72, 0.66],
                     [0.40, 0.42, 0.46], [0.70, 0.55, 0.35], [0.30, 0.33, 0.38],
                     [0.80, 0.78, 0.74], [0.52, 0.40, 0.30]], dtype=np.float32)
_GLASS = np.array([0.05, 0.08, 0.12], dtype=np.float32)
_LIT = np.array([0.95, 0.80, 0.45], dtype=np.float32)


def voxel_city_heights(size: int = 128, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Height field and cell colours of the voxel city (peak ``max(12, 0.45 size)`` voxels).

    Parameters
    ----------
    size, seed : int, optional
        Cells along each side of the grid (4..4096), and the random seed (>= 0).

    Returns
    -------
    h, kind : numpy.ndarray
        ``(size, size)`` int64: ``h[i, j]`` the column height in voxels (>= 0) of cell ``i``
        along x, ``j`` along z; ``kind[i, j]`` the cell's material: 0 asphalt, 1 sidewalk,
        2 grass, 3 tree, ``4 + k`` building facade ``k``.
    """
    size = check_int("size", size, 4, 4096)
    seed = check_int("seed", seed, 0)
    rng = np.random.default_rng(seed)
    h = np.zeros((size, size), dtype=np.int64)
    kind = np.full((size, size), _ASPHALT, dtype=np.int64)
    peak = max(12, int(0.45 * size))
    p = BLOCK_PITCH
    for bi in range(0, size, p):
        for bj in range(0, size, p):
            # Block interior, after the 2-cell street; clipped at the grid border.
            x0, z0 = bi + 2, bj + 2
            x1, z1 = min(bi + p, size), min(bj + p, size)
            if x1 - x0 < 3 or z1 - z0 < 3:
                continue
            kind[x0:x1, z0:z1] = _SIDEWALK
            ix0, iz0, ix1, iz1 = x0 + 1, z0 + 1, x1 - 1, z1 - 1   # inside the sidewalk ring
            # Downtown factor: 1 at the centre of the grid, falling off towards the edges.
            cx, cz = (bi + p / 2) / size - 0.5, (bj + p / 2) / size - 0.5
            downtown = math.exp(-4.0 * (cx * cx + cz * cz))
            # Split the interior into up to 2 x 2 lots separated by 1-cell alleys.
            sx, sz = [(ix0, ix1)], [(iz0, iz1)]
            if ix1 - ix0 >= 5 and rng.random() < 0.75:
                a = int(rng.integers(ix0 + 2, ix1 - 2))
                sx = [(ix0, a), (a + 1, ix1)]
            if iz1 - iz0 >= 5 and rng.random() < 0.75:
                a = int(rng.integers(iz0 + 2, iz1 - 2))
                sz = [(iz0, a), (a + 1, iz1)]
            park = rng.random() < 0.08
            for a, b in sx:
                for c, d in sz:
                    if park:
                        kind[a:b, c:d] = _GRASS
                        trees = rng.random((b - a, d - c)) < 0.3
                        h[a:b, c:d][trees] = rng.integers(1, 3, size=int(trees.sum()))
                        kind[a:b, c:d][trees] = _TREE
                        continue
                    height = int(round(peak * downtown * rng.uniform(0.3, 1.0)
                                       + rng.integers(2, 3 + peak // 8)))
                    h[a:b, c:d] = height
                    kind[a:b, c:d] = _BUILDING + int(rng.integers(len(_FACADES)))
                    # A set-back tower on big, tall lots.
                    if b - a >= 3 and d - c >= 3 and height >= 8 and rng.random() < 0.6:
                        h[a + 1:b - 1, c + 1:d - 1] += int(rng.integers(3, max(4, height // 2)))
    return h, kind


def _side_counts(h: np.ndarray) -> list[np.ndarray]:
    """Exposed side voxel faces per cell towards +x, -x, +z, -z (height 0 outside the grid)."""
    hp = np.pad(h, 1)
    c = hp[1:-1, 1:-1]
    return [np.maximum(c - hp[2:, 1:-1], 0), np.maximum(c - hp[:-2, 1:-1], 0),
            np.maximum(c - hp[1:-1, 2:], 0), np.maximum(c - hp[1:-1, :-2], 0)]


def voxel_city_triangle_count(size: int = 128, seed: int = 0) -> int:
    """Triangles of the voxel city mesh plus its ground plane (formula in the module docs).

    Parameters
    ----------
    size : int, optional
        Cells along each side of the grid.
    seed : int, optional
        The city's random seed.

    Returns
    -------
    count : int
        The triangle count ``T``.
    """
    h, _ = voxel_city_heights(size, seed)
    return 2 * (h.size + int(sum(int(s.sum()) for s in _side_counts(h)))) + 2


def _quads(p: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Corners (Q, 4, 3) of quads ``p, p+u, p+u+v, p+v``; the face normal is ``u x v``."""
    return np.stack([p, p + u, p + u + v, p + v], axis=1)


def _base_colour(k: np.ndarray) -> np.ndarray:
    """Colour of each cell kind (ground kinds, then one facade per building kind)."""
    out = np.empty((k.size, 3), dtype=np.float32)
    b = k >= _BUILDING
    out[~b] = _KIND_COLOURS[k[~b]]
    out[b] = _FACADES[k[b] - _BUILDING]
    return out


def _voxel_city_quads(size: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Corners (Q, 4, 3) in voxel units and colours (Q, 3) of the city's visible faces."""
    h, kind = voxel_city_heights(size, seed)
    n = size
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    ii, jj, hh, kk = ii.ravel(), jj.ravel(), h.ravel(), kind.ravel()
    ex, ey, ez = np.eye(3, dtype=np.float64)

    # Tops: one per cell (roofs are a darker facade colour).
    p = np.stack([ii, hh, jj], axis=1).astype(np.float64)
    corners = [_quads(p, np.broadcast_to(ez, p.shape), np.broadcast_to(ex, p.shape))]
    top = _base_colour(kk)
    top[kk >= _BUILDING] *= 0.6
    colours = [top]

    # Sides: one quad per exposed voxel face, face normal pointing out of the column.
    # (direction, corner offset, u, v, coordinate along the facade for windows)
    sides = [(ex, ex, ey, ez, jj), (-ex, 0 * ex, ez, ey, jj), (ez, ez, ex, ey, ii),
             (-ez, 0 * ez, ey, ex, ii)]
    hash_rng = np.random.default_rng(seed + 1)
    for count, (_, off, u, v, along) in zip(_side_counts(h), sides):
        cnt = count.ravel()
        total = int(cnt.sum())
        if total == 0:
            continue
        cell = np.repeat(np.arange(n * n), cnt)
        # Voxel level of each face: from the neighbour's height up to the cell's.
        level = (np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
                 + np.repeat(hh - cnt, cnt))
        p = np.stack([ii[cell], level, jj[cell]], axis=1).astype(np.float64) + off
        corners.append(_quads(p, np.broadcast_to(u, p.shape), np.broadcast_to(v, p.shape)))
        col = _base_colour(kk[cell])
        # Windows: every third storey, every other voxel along the facade; some lit.
        win = (kk[cell] >= _BUILDING) & (level % 3 == 1) & (along[cell] % 2 == 0)
        lit = hash_rng.random(total) < 0.2
        col[win] = _GLASS
        col[win & lit] = _LIT
        colours.append(col)
    return np.concatenate(corners), np.concatenate(colours)


def _voxel_city_mesh(size: int, seed: int) -> "mi.Mesh":
    corners, colours = _voxel_city_quads(size, seed)     # (Q, 4, 3) voxel units, (Q, 3)
    n = size
    q = corners.shape[0]
    # Voxel grid -> world: centred at the origin, CITY_EXTENT wide, y up.
    scale = CITY_EXTENT / n
    verts = (corners.reshape(-1, 3) - [n / 2, 0.0, n / 2]) * scale
    base = 4 * np.arange(q, dtype=np.uint32)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    face_colours = np.repeat(colours, 2, axis=0)

    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "diffuse",
                                  "reflectance": {"type": "mesh_attribute",
                                                  "name": "face_color"}})
    props["face_normals"] = True
    mesh = mi.Mesh("voxel-city", 4 * q, 2 * q, props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(verts.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
    params.update()
    mesh.add_attribute("face_color", 3, mi.Float(face_colours.astype(np.float32).ravel()))
    return mesh


def _sky_bitmap(width: int = 64, height: int = 32) -> "mi.Bitmap":
    """Lat-long sky: deep blue at the zenith, pale at the horizon, brown-grey ground below."""
    theta = (np.arange(height) + 0.5) / height * np.pi          # 0 at +y (zenith)
    elevation = np.cos(theta)[:, None, None]                     # sin(altitude)
    zenith = np.array([0.18, 0.32, 0.75])
    horizon = np.array([0.75, 0.85, 1.0])
    ground = np.array([0.22, 0.25, 0.16])
    t = np.clip(elevation, 0.0, 1.0) ** 0.5
    sky = horizon * (1 - t) + zenith * t
    img = np.where(elevation > 0, sky, ground) * np.ones((1, width, 1))
    return mi.Bitmap(img.astype(np.float32))


def _voxel_city(size: int = 128, seed: int = 0, envmap: bool = True, sun: bool = True) -> dict:
    """Voxel city: ``size`` cells per side (>= 4), random layout ``seed``, sky and sun switches."""
    size = check_int("size", size, 4, 4096)
    seed = check_int("seed", seed, 0)
    for name, value in (("envmap", envmap), ("sun", sun)):
        if not isinstance(value, bool):
            raise ParameterError(name, value, "True or False")
    half = 25 * CITY_EXTENT           # ground plane reaching the horizon
    d = {
        "city": _voxel_city_mesh(size, seed),
        "ground": {"type": "rectangle",
                   "to_world": mi.ScalarTransform4f().translate([0.0, -0.02, 0.0])
                   @ mi.ScalarTransform4f().scale([half, 1.0, half])
                   @ mi.ScalarTransform4f().rotate([1, 0, 0], -90),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                               "value": [0.22, 0.25, 0.16]}}},
    }
    if envmap:
        d["sky"] = {"type": "envmap", "bitmap": _sky_bitmap(), "scale": 1.0}
    if sun:
        d["sun"] = {"type": "directional", "direction": [0.45, -0.8, 0.35],
                    "irradiance": {"type": "rgb", "value": [3.2, 3.0, 2.7]}}
    return d
