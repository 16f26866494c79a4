"""The skin: the outer head surface meshed by rays over a (polar, azimuth) grid.

Rays from the head centre over a grid that is dense over the face meet the implicit shape;
below 150 degrees from +y the rays leave from origins sliding down the neck axis, so no ray
grazes the neck. The grid row through the mouth line is cut between the mouth corners: the
row's vertices are duplicated, faces above use the upper copies and faces below the lower
copies, so at rest the mouth is closed and a deformation opens it. Positions are in the head
frame, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.synth.shape import _Shape, _smoothstep, _trace

# grid resolution: azimuth columns (even, symmetric about 0) and polar rows
_N_AZ_HALF = 120
_N_POLAR = 180
_N_NECK = 40
_PHI_NECK = np.deg2rad(150.0)
_NECK_ORIGIN_Y = -245.0


def _warped(n: int, lo: float, hi: float, floor: float, *bands: tuple[float, float, float]):
    """``n`` samples on [lo, hi] (both included) with density ``floor`` plus ``(a, b, w)`` bands.

    Each band adds density ``w`` (smoothly) between ``a`` and ``b``.

    Returns
    -------
    (n,) float64
        Increasing samples, in the units of ``lo`` and ``hi``.
    """
    t = np.linspace(lo, hi, 4097)
    soft = 0.04 * (hi - lo)
    rho = np.full_like(t, floor)
    for a, b, w in bands:
        rho += w * 0.5 * (np.tanh((t - a) / soft) - np.tanh((t - b) / soft))
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (rho[1:] + rho[:-1]) * np.diff(t))])
    return np.interp(np.linspace(0.0, cdf[-1], n), cdf, t)


@dataclass(frozen=True)
class _Grid:
    """The ray grid: one ray per (row, column) node, plus one ray up and one down the neck.

    Attributes
    ----------
    az : (A,) float64
        Azimuth of each column about y, rad (0 = +z), symmetric about 0.
    phi : (R,) float64
        Polar angle of each row from +y, rad.
    y_org : (R,) float64
        Height of each row's ray origin on the y axis, mm.
    row_mouth : int
        The row through the mouth line.
    phi_mouth : float
        Polar angle of the mouth line, rad.
    """

    az: np.ndarray
    phi: np.ndarray
    y_org: np.ndarray
    row_mouth: int
    phi_mouth: float

    @property
    def n_az(self) -> int:
        """Number of columns."""
        return len(self.az)

    @property
    def size(self) -> int:
        """Number of (row, column) nodes."""
        return len(self.phi) * len(self.az)

    def index(self, i, j):
        """Node index of row ``i``, column ``j`` (columns wrap around)."""
        return i * self.n_az + (j % self.n_az)


@dataclass(frozen=True)
class _Slit:
    """The cut along the mouth line.

    Attributes
    ----------
    upper, lower : (S,) int64
        Vertex indices of the upper and lower copies along the slit (corners excluded),
        left to right.
    corner_l, corner_r : int
        Vertex indices of the mouth corners (x < 0 and x > 0).
    """

    upper: np.ndarray
    lower: np.ndarray
    corner_l: int
    corner_r: int


@dataclass(frozen=True)
class _Mouth:
    """The mouth at rest.

    Attributes
    ----------
    corner_x : float
        Half the distance between the corners, mm.
    y, z : float
        Height and depth of the mouth centre, mm.
    corner_y : float
        Mean height of the corners, mm.
    line_x, line_y : (S + 2,) float64
        The mouth line (the lips meet along it) from corner to corner, mm.
    """

    corner_x: float
    y: float
    z: float
    corner_y: float
    line_x: np.ndarray
    line_y: np.ndarray

    @classmethod
    def at_rest(cls, verts: np.ndarray, slit: _Slit, centre: int) -> _Mouth:
        """The mouth of rest vertices (N, 3) cut by ``slit`` whose centre vertex is ``centre``."""
        cl, cr = verts[slit.corner_l], verts[slit.corner_r]
        return cls(
            corner_x=float(0.5 * (cr[0] - cl[0])),
            y=float(verts[centre, 1]),
            z=float(verts[centre, 2]),
            corner_y=float(0.5 * (cl[1] + cr[1])),
            line_x=np.concatenate([[cl[0]], verts[slit.upper, 0], [cr[0]]]),
            line_y=np.concatenate([[cl[1]], verts[slit.upper, 1], [cr[1]]]),
        )

    def as_dict(self) -> dict[str, float]:
        """``corner_x``, ``y``, ``z`` and ``corner_y`` (see :attr:`HeadModel.mouth`)."""
        return {"corner_x": self.corner_x, "y": self.y, "z": self.z, "corner_y": self.corner_y}

    def line(self, x):
        """Height of the mouth line at ``x`` (mm; array or scalar), mm."""
        return np.interp(x, self.line_x, self.line_y)

    def vermilion(self, x, lips: float) -> tuple[np.ndarray, np.ndarray]:
        """Heights of the upper and lower vermilion borders above/below the mouth line.

        Parameters
        ----------
        x : (N,) float64
            Positions across the mouth, mm.
        lips : float
            The identity's lip thickness factor.

        Returns
        -------
        upper, lower : (N,) float64
            mm.
        """
        u = np.clip(np.abs(x) / self.corner_x, 0.0, 1.0)
        taper = np.sqrt(np.clip(1.0 - u**2.2, 0.0, 1.0))
        bow = (
            1.0 + 0.16 * np.exp(-(((np.abs(x) - 6.0) / 3.5) ** 2)) - 0.1 * np.exp(-((x / 2.5) ** 2))
        )
        return 8.0 * lips * taper * bow, 9.5 * lips * taper

    def coords(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mouth-relative coordinates of positions ``p`` (N, 3).

        Returns
        -------
        s : (N,) float64
            Height above the mouth line, mm.
        u : (N,) float64
            ``x / corner_x``: -1 and 1 at the corners.
        """
        s = p[:, 1] - self.line(p[:, 0])
        return s, p[:, 0] / self.corner_x


@dataclass(frozen=True)
class _Skin:
    """The skin mesh.

    Attributes
    ----------
    vertices : (V, 3) float64
        The grid nodes, the two pole vertices, then the lower copies of the slit, mm.
    faces : (F, 3) int64
        Triangles, counter-clockwise seen from outside.
    slit : _Slit
    mouth : _Mouth
    """

    vertices: np.ndarray
    faces: np.ndarray
    slit: _Slit
    mouth: _Mouth


def _grid(shape: _Shape) -> _Grid:
    """The ray grid of a shape: dense over the face, with a row exactly on the mouth line.

    Rows run from the head centre down to 150 degrees from +y, then (for the neck) at 150
    degrees from origins sliding down the neck axis. They are denser from the nose tip to the
    chin, where the lips and nostrils face up or down.
    """
    a_half = _warped(_N_AZ_HALF + 1, 0.0, np.pi, 0.15, (-1.0, np.deg2rad(95.0), 0.85))
    az = np.concatenate([-a_half[:0:-1], a_half[:-1]])  # [-pi, ..., 0, ...), symmetric
    phi = _warped(
        _N_POLAR + 1,
        0.0,
        _PHI_NECK,
        0.2,
        (np.deg2rad(38.0), _PHI_NECK + 1.0, 0.8),
        (np.deg2rad(97.0), np.deg2rad(135.0), 1.2),
    )[1:]
    phi_m = np.pi / 2 + np.arctan2(-shape.stomion_y, shape.lip_front_z)
    i_m = int(np.argmin(np.abs(phi - phi_m)))
    off = phi_m - phi[i_m]
    phi = phi + off * np.exp(-np.abs(np.arange(len(phi)) - i_m) / 3.0)
    y_org = np.concatenate(
        [np.zeros(len(phi)), _NECK_ORIGIN_Y * (np.arange(1, _N_NECK + 1) / _N_NECK) ** 1.3]
    )
    phi = np.concatenate([phi, np.full(_N_NECK, _PHI_NECK)])
    return _Grid(az=az, phi=phi, y_org=y_org, row_mouth=i_m, phi_mouth=phi_m)


def _cast(shape: _Shape, grid: _Grid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cast the grid's rays (nodes, then up from the centre, then down the neck).

    Returns
    -------
    origins, dirs : (grid.size + 2, 3) float64
        Ray origins (mm) and unit directions.
    r : (grid.size + 2,) float64
        Distance to the surface along each ray, mm.
    """
    P, A = np.meshgrid(grid.phi, grid.az, indexing="ij")
    dirs = np.stack([np.sin(P) * np.sin(A), np.cos(P), np.sin(P) * np.cos(A)], -1).reshape(-1, 3)
    poles = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    all_dirs = np.concatenate([dirs, poles])
    origins = np.zeros_like(all_dirs)
    origins[: grid.size, 1] = np.repeat(grid.y_org, grid.n_az)
    origins[-1, 1] = _NECK_ORIGIN_Y
    return origins, all_dirs, _trace(shape, origins, all_dirs)


def _mouth_columns(shape: _Shape, grid: _Grid, dirs: np.ndarray, r: np.ndarray) -> int:
    """Columns from the centre to a mouth corner: the front column nearest the half-width.

    ``dirs`` and ``r`` are the rays of :func:`_cast`; the mouth row's rays leave from the origin.
    """
    row = slice(grid.row_mouth * grid.n_az, (grid.row_mouth + 1) * grid.n_az)
    x_row = (dirs[row] * r[row][:, None])[:, 0]
    az = grid.az
    front = np.abs(az) < np.pi / 2
    kc = int(np.argmin(np.where(front & (az >= 0), np.abs(x_row - shape.mouth_half_width), np.inf)))
    return kc - _N_AZ_HALF


def _crease(grid: _Grid, r: np.ndarray, kc: int) -> np.ndarray:
    """Ray distances ``r`` (mm) with a shallow groove along the mouth line where the lips meet.

    ``kc`` is the number of columns from the centre to a mouth corner.
    """
    n_ph = len(grid.phi)
    rr = r[: grid.size].reshape(n_ph, grid.n_az)
    a_c = grid.az[_N_AZ_HALF + kc]
    span = 1.0 - _smoothstep(np.abs(grid.az), a_c - np.deg2rad(4.0), a_c + np.deg2rad(6.0))
    crease = 2.2 * np.exp(-((((grid.phi[:, None] - grid.phi_mouth) * rr) / 1.6) ** 2))
    out = r.copy()
    out[: grid.size] = (rr - crease * span[None, :]).reshape(-1)
    return out


def _faces(grid: _Grid, kc: int) -> tuple[np.ndarray, _Slit]:
    """Triangles of the grid with the pole caps, cut along the mouth row between the corners.

    The lower copies of the slit vertices are numbered after the grid nodes and the poles.
    """
    n_ph, n_az, n_grid, i_m, j0 = len(grid.phi), grid.n_az, grid.size, grid.row_mouth, _N_AZ_HALF
    gid = grid.index
    top, bottom = n_grid, n_grid + 1
    I, J = np.meshgrid(np.arange(n_ph - 1), np.arange(n_az), indexing="ij")
    I, J = I.reshape(-1), J.reshape(-1)
    a, b, c, d = gid(I, J), gid(I + 1, J), gid(I, J + 1), gid(I + 1, J + 1)
    quads_lower_band = I == i_m  # faces between row i_m and i_m + 1 (below the mouth row)
    tri1 = np.stack([a, b, c], 1)
    tri2 = np.stack([b, d, c], 1)
    jj = np.arange(n_az)
    cap_top = np.stack([np.full(n_az, top), gid(0, jj), gid(0, jj + 1)], 1)
    cap_bot = np.stack([gid(n_ph - 1, jj + 1), gid(n_ph - 1, jj), np.full(n_az, bottom)], 1)

    # the slit: faces below the mouth row use lower copies of its interior
    slit_cols = np.arange(j0 - kc + 1, j0 + kc)
    slit = _Slit(
        upper=gid(i_m, slit_cols),
        lower=n_grid + 2 + np.arange(len(slit_cols)),
        corner_l=gid(i_m, j0 - kc),
        corner_r=gid(i_m, j0 + kc),
    )
    remap_lower = np.arange(n_grid + 2)
    remap_lower[slit.upper] = slit.lower
    lower_band = np.concatenate([quads_lower_band, quads_lower_band])
    tris = np.concatenate([tri1, tri2])
    tris = np.where(lower_band[:, None], remap_lower[tris], tris)
    return np.concatenate([cap_top, tris, cap_bot]), slit


def _mesh_skin(shape: _Shape) -> _Skin:
    """Mesh the outer surface of a shape, cut along the mouth line.

    Parameters
    ----------
    shape : _Shape

    Returns
    -------
    _Skin
    """
    grid = _grid(shape)
    origins, dirs, r = _cast(shape, grid)
    kc = _mouth_columns(shape, grid, dirs, r)
    r = _crease(grid, r, kc)
    nodes = origins + dirs * r[:, None]
    faces, slit = _faces(grid, kc)
    verts = np.concatenate([nodes, nodes[slit.upper]])
    centre = grid.index(grid.row_mouth, _N_AZ_HALF)
    return _Skin(verts, faces, slit, _Mouth.at_rest(verts, slit, centre))
