"""Skin detail: freckles, moles and mottling fixed to the skin, so that they move with it.

Real colour images of skin carry detail at the scales a 640 x 480 face image resolves (freckles,
moles, blotches of a few millimetres). A method that follows the skin by its colour (image
correlation, optical flow) needs that detail to be measured, and the detail must be *material*:
a freckle stays on the same skin point however the face deforms. So the detail is a function of
the **rest position** (the neutral head-frame position, mm) of the skin point a pixel sees, found
by ray casting the deformed mesh and interpolating the rest positions of the hit triangle with the
hit's barycentric coordinates. All randomness is a hash of integer lattice cells and a seed: the
same subject has the same freckles in every take, and no generator state is involved.
"""

from __future__ import annotations

import hashlib

import numpy as np

from scan2morph.geometry import in_blocks
from scan2morph.open3d_light import open3d, triangle_scene

#: Odd 64-bit multipliers combining the three lattice coordinates into one hash key.
_HASH_MUL = (
    np.uint64(0x9E3779B97F4A7C15),
    np.uint64(0xC2B2AE3D27D4EB4F),
    np.uint64(0x165667B19E3779F9),
)
#: Freckles and moles: lattice cell (mm), chance of a spot per cell, radius (mm) and darkness.
_SPOT_CELL_MM = 5.0
_SPOT_CHANCE = 0.1
_SPOT_RADIUS_MM = (0.6, 1.8)
_SPOT_DARKNESS = (0.1, 0.45)
#: Darkening of a spot per channel (brown: blue and green lose more than red).
_SPOT_TINT = np.array([0.6, 0.85, 1.0])
#: Mottling (blotches and pores): value-noise cells (mm) and their amplitudes.
_MOTTLE = ((3.0, 0.035), (1.2, 0.025))
#: Points whose skin detail or value noise is computed together (:func:`skin_detail`).
_BLOCK = 65536


def texture_seed(subject: str, seed: int) -> int:
    """The skin-detail seed of a synthetic subject, fixed by ``(seed, subject)``."""
    digest = hashlib.sha256(f"skin/{subject}".encode()).digest()[:8]
    return (int.from_bytes(digest, "little") ^ int(seed)) & 0xFFFFFFFFFFFFFFFF


def mix_uniform(h: np.ndarray) -> np.ndarray:
    """Uniform [0, 1) values from uint64 keys (splitmix64's finaliser), same shape."""
    h = h ^ (h >> np.uint64(30))
    h *= np.uint64(0xBF58476D1CE4E5B9)
    h ^= h >> np.uint64(27)
    h *= np.uint64(0x94D049BB133111EB)
    h ^= h >> np.uint64(31)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def _cell_uniform(cells: np.ndarray, seed: int) -> np.ndarray:
    """(n,) uniform [0, 1) value of integer lattice cells (n, 3) under ``seed``."""
    c = cells.astype(np.uint64)
    return mix_uniform(
        c[:, 0] * _HASH_MUL[0] ^ c[:, 1] * _HASH_MUL[1] ^ c[:, 2] * _HASH_MUL[2] ^ np.uint64(seed)
    )


def value_noise(points: np.ndarray, cell_mm: float, seed: int) -> np.ndarray:
    """Solid value noise: uniform values on a cubic lattice, interpolated trilinearly.

    Parameters
    ----------
    points : (n, 3) float
        Positions, mm.
    cell_mm : float
        Lattice spacing, mm (the feature size).
    seed : int
        Fixes the pattern (0 <= seed < 2**64).

    Returns
    -------
    (n,) float64
        In [0, 1], mean 0.5, standard deviation about 0.12.
    """
    # each point's value is its own: cache-sized blocks, the same numbers
    return in_blocks(
        lambda p: _noise_block(p, cell_mm, seed), np.asarray(points, dtype=np.float64), _BLOCK
    )


def _noise_block(points: np.ndarray, cell_mm: float, seed: int) -> np.ndarray:
    """:func:`value_noise` of one block of positions (n, 3) float64, mm; (n,)."""
    q = points / float(cell_mm)
    base = np.floor(q)
    frac = q - base
    base = base.astype(np.int64)
    weights = [(1.0 - frac[:, k], frac[:, k]) for k in range(3)]
    # per axis and corner offset: the lattice coordinate times that axis's hash multiplier
    keys = [[(base[:, k] + d).astype(np.uint64) * _HASH_MUL[k] for d in (0, 1)] for k in range(3)]
    value = np.zeros(len(q))
    for dx, dy, dz in np.ndindex(2, 2, 2):
        h = keys[0][dx] ^ keys[1][dy] ^ keys[2][dz] ^ np.uint64(seed)
        value += weights[0][dx] * weights[1][dy] * weights[2][dz] * mix_uniform(h)
    return value


def _spots(points: np.ndarray, seed: int) -> np.ndarray:
    """(n,) darkness in [0, 1) of freckles and moles at rest positions (n, 3), mm.

    One candidate spot per lattice cell (present with :data:`_SPOT_CHANCE`) at a random place in
    the cell, with a random radius and darkness and a Gaussian profile; overlapping spots combine
    multiplicatively.
    """
    light = np.ones(len(points))
    if len(points) == 0:
        return 1.0 - light
    # the draws are made once per distinct cell, then handed to the points in it
    base = np.floor(points / _SPOT_CELL_MM).astype(np.int64)
    index = base - base.min(axis=0)
    span = index.max(axis=0) + 1
    key = (index[:, 0] * span[1] + index[:, 1]) * span[2] + index[:, 2]
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    cells, inverse = base[first], inverse.reshape(-1)
    draws = [seed ^ (0x51ED2701 * (k + 1)) for k in range(6)]
    for offset in np.ndindex(3, 3, 3):
        cell = cells + np.asarray(offset) - 1
        u = [_cell_uniform(cell, d & 0xFFFFFFFFFFFFFFFF) for d in draws]
        present = u[0] < _SPOT_CHANCE
        if not present.any():
            continue
        at = np.flatnonzero(present[inverse])  # points beside a spot; the others keep light
        k = inverse[at]
        centre = (cell[k] + np.stack([v[k] for v in u[1:4]], axis=1)) * _SPOT_CELL_MM
        radius = _SPOT_RADIUS_MM[0] + u[4][k] * (_SPOT_RADIUS_MM[1] - _SPOT_RADIUS_MM[0])
        dark = _SPOT_DARKNESS[0] + u[5][k] * (_SPOT_DARKNESS[1] - _SPOT_DARKNESS[0])
        d2 = np.sum((points[at] - centre) ** 2, axis=1)
        light[at] *= 1.0 - dark * np.exp(-0.5 * d2 / (0.6 * radius) ** 2)
    return 1.0 - light


def skin_detail(points: np.ndarray, seed: int, strength: float = 1.0) -> np.ndarray:
    """Multiplicative albedo factor of the skin detail at rest positions.

    Parameters
    ----------
    points : (n, 3) float
        Rest (neutral head-frame) positions of skin points, mm.
    seed : int
        The subject's texture seed (0 <= seed < 2**64).
    strength : float
        Scales every amplitude; 0 gives 1 everywhere (flat albedo), 1 a lightly freckled skin.

    Returns
    -------
    (n, 3) float64
        Factor per RGB channel, positive; multiply the albedo by it.
    """
    # every point's factor is its own (the draws are hashes of its cells): cache-sized blocks,
    # the same numbers, about 1.5x faster on the million sub-pixels of a supersampled image
    return in_blocks(
        lambda p: _detail_block(p, seed, strength), np.asarray(points, dtype=np.float64), _BLOCK
    )


def _detail_block(p: np.ndarray, seed: int, strength: float) -> np.ndarray:
    """:func:`skin_detail` of one block of rest positions (n, 3) float64, mm; (n, 3)."""
    out = np.ones((len(p), 3))
    if strength <= 0 or len(p) == 0:
        return out
    for k, (cell, amp) in enumerate(_MOTTLE):
        n = value_noise(p, cell, (seed + 0x9E37 * (k + 1)) & 0xFFFFFFFFFFFFFFFF)
        out *= (1.0 + strength * amp * (n - 0.5) / 0.12)[:, None]
    out *= 1.0 - np.clip(strength * _spots(p, seed), 0.0, 0.95)[:, None] * _SPOT_TINT
    return np.clip(out, 0.05, None)


def rest_positions(
    vertices_cam: np.ndarray, faces: np.ndarray, rest: np.ndarray, rays: np.ndarray
) -> np.ndarray:
    """Rest position of the surface point each camera ray meets first.

    Parameters
    ----------
    vertices_cam : (N, 3) float
        The deformed mesh in the camera frame, mm.
    faces : (F, 3) int
    rest : (N, 3) float
        Rest positions of the same vertices (any frame), mm.
    rays : (n, 3) float
        Ray directions from the camera centre (the origin).

    Returns
    -------
    (n, 3) float64
        Rest positions, NaN where a ray misses the mesh.
    """
    o3d = open3d()
    scene = triangle_scene(vertices_cam, faces)
    r = np.concatenate([np.zeros_like(rays), rays], axis=1).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(r))
    found = np.isfinite(hit["t_hit"].numpy())
    prim = hit["primitive_ids"].numpy().astype(np.int64)[found]
    uv = hit["primitive_uvs"].numpy().astype(np.float64)[found]
    tri = np.asarray(faces, dtype=np.int64)[prim]
    bary = np.column_stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]])
    out = np.full((len(rays), 3), np.nan)
    out[found] = np.einsum("nk,nkd->nd", bary, np.asarray(rest, dtype=np.float64)[tri])
    return out


def detail_image(
    where: np.ndarray,
    vertices_cam: np.ndarray,
    faces: np.ndarray,
    rest: np.ndarray,
    K: np.ndarray,
    seed: int,
    strength: float,
    supersample: int = 2,
) -> np.ndarray:
    """Skin-detail factor of every pixel of a pinhole image, averaged over sub-pixels.

    Parameters
    ----------
    where : (H, W) bool
        Pixels to texture (the skin); the others get 1.
    vertices_cam, faces, rest
        As in :func:`rest_positions`.
    K : (3, 3) float
        Intrinsics, pixel centres at integer coordinates.
    seed, strength
        As in :func:`skin_detail`.
    supersample : int
        Sub-pixels per pixel and axis (the factor is their mean: no aliasing of detail finer
        than a pixel).

    Returns
    -------
    (H, W, 3) float64
        Multiplicative factor; 1 outside ``where`` and where a sub-pixel ray misses.
    """
    out = np.ones((*where.shape, 3))
    if strength <= 0 or not where.any():
        return out
    rows, cols = np.nonzero(where)
    s = int(supersample)
    sub = (np.arange(s) + 0.5) / s - 0.5
    Kinv = np.linalg.inv(K)
    rays = [
        np.column_stack([cols + dx, rows + dy, np.ones(len(rows))]) @ Kinv.T
        for dy in sub
        for dx in sub
    ]
    # one ray cast for every sub-pixel: the scene's acceleration structure is built once
    points = np.split(rest_positions(vertices_cam, faces, rest, np.concatenate(rays)), s * s)
    factor = np.zeros((len(rows), 3))
    for p in points:
        hit = np.isfinite(p).all(axis=1)
        f = np.ones((len(rows), 3))
        f[hit] = skin_detail(p[hit], seed, strength)
        factor += f
    out[rows, cols] = factor / (s * s)
    return out
