"""Finite element model of a surface mesh as a thin shell (stiffness and mass matrices).

Each triangle of the neutral mesh becomes a three-node shell element with membrane and bending
stiffness (pyfe3d's ``Tria3DSG`` by default, ``Tria3R`` on request; see :func:`assemble`), six
degrees of freedom per node in the order ``u, v, w, r_x, r_y, r_z`` (translations in mm,
rotations in radians, in the global frame of the mesh). Global DOF ``6 * i + j`` is component
``j`` of vertex ``i``.

Units are the consistent set mm, N, tonne, s: lengths in mm, Young's modulus in N/mm^2 (= MPa),
density in t/mm^3 (steel: 7.85e-9), so that ``K`` is in N/mm (translations), ``M`` in tonnes and
``sqrt(eig(K, M)) / (2 pi)`` comes out in Hz. The material only scales the frequencies (and the
Poisson ratio weakly changes the shapes), as the modal analysis paper notes; what shapes the
modes is the geometry, the fixed boundary and the thickness map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from scan2morph import tol
from scan2morph.errors import InputError
from scan2morph.geometry import boundary_edges

#: Degrees of freedom per node: u, v, w, r_x, r_y, r_z.
DOF = 6

_ELEMENTS = ("tria3r", "tria3dsg")
_MASS_TYPES = {"consistent": 0, "lumped": 1, "vertex": 1}


@dataclass(frozen=True)
class ShellMaterial:
    """Isotropic shell material in the mm / N / tonne / s unit system.

    Parameters
    ----------
    youngs_modulus_mpa : float
        Young's modulus E, N/mm^2 (MPa). Default: steel, 210000.
    poisson_ratio : float
        Poisson's ratio nu, in (-1, 0.5). Default 0.3.
    density_t_per_mm3 : float
        Mass density rho, tonne/mm^3. Default: steel, 7.85e-9.
    membrane_scale : float
        Factor on the membrane (in-plane) stiffness ``A = E t / (1 - nu^2) ...`` of the shell,
        > 0; bending and transverse shear keep their values. 1 (default) is the plain shell;
        below 1 a membrane-softened shell, whose in-plane modes (the skin sliding over the
        face) come earlier relative to its bending modes. The drilling stiffness follows
        ``A66``.
    rotary_inertia : bool
        Keep the rotary inertia ``rho t^3 / 12`` of the rotations (True, the plain shell).
        False gives the rotations no mass: the mass inner product then weighs translations
        only, so that ``Q^T M v`` of a field given by its translations is the mass-weighted
        least squares of those translations.
    """

    youngs_modulus_mpa: float = 210000.0
    poisson_ratio: float = 0.3
    density_t_per_mm3: float = 7.85e-9
    membrane_scale: float = 1.0
    rotary_inertia: bool = True

    def check(self, source: str) -> None:
        """Raise :class:`InputError` unless E > 0, rho > 0, -1 < nu < 0.5 and the membrane
        scale > 0."""
        if not (np.isfinite(self.membrane_scale) and self.membrane_scale > 0):
            raise InputError(
                source, f"membrane_scale: expected a positive number, got {self.membrane_scale}"
            )
        e, nu, rho = self.youngs_modulus_mpa, self.poisson_ratio, self.density_t_per_mm3
        if not (np.isfinite(e) and e > 0):
            raise InputError(source, f"youngs_modulus_mpa: expected a positive number, got {e}")
        if not (np.isfinite(rho) and rho > 0):
            raise InputError(source, f"density_t_per_mm3: expected a positive number, got {rho}")
        if not (np.isfinite(nu) and -1.0 < nu < 0.5):
            raise InputError(source, f"poisson_ratio: expected a number in (-1, 0.5), got {nu}")


def check_mesh(
    vertices: ArrayLike, faces: ArrayLike, source: str = "mesh"
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Validate a triangle mesh for the shell model.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int, counter-clockwise vertex indices
    source : str
        Label for error messages.

    Returns
    -------
    vertices : (V, 3) float64, C-contiguous
    faces : (F, 3) int64

    Raises
    ------
    InputError
        Wrong shapes, non-finite coordinates, indices out of range, or a degenerate triangle
        (area below ``tol.AREA_EPS`` mm^2; the message names the first such face index).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3:
        raise InputError(source, f"vertices: expected shape (V, 3) with V >= 3, got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise InputError(source, "vertices: expected finite coordinates, found NaN or inf")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] < 1:
        raise InputError(source, f"faces: expected shape (F, 3) with F >= 1, got {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        raise InputError(source, f"faces: expected integer indices, got dtype {f.dtype}")
    f = f.astype(np.int64)
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise InputError(
            source, f"faces: indices must lie in [0, {v.shape[0] - 1}], got [{f.min()}, {f.max()}]"
        )
    areas = face_areas(v, f)
    bad = np.flatnonzero(~(areas >= tol.AREA_EPS))
    if bad.size:
        raise InputError(
            source,
            f"faces: triangle {bad[0]} is degenerate (area {areas[bad[0]]:.3g} mm^2 < "
            f"{tol.AREA_EPS:g}); {bad.size} degenerate face(s) in total",
        )
    return np.ascontiguousarray(v), f


def face_areas(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Triangle areas.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int

    Returns
    -------
    (F,) float, mm^2
    """
    p = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def boundary_vertices(faces: ArrayLike, n_vertices: int | None = None) -> NDArray[np.bool_]:
    """Vertices on the mesh boundary: ends of edges used by exactly one face.

    Parameters
    ----------
    faces : (F, 3) int
    n_vertices : int, optional
        Length of the returned mask; default ``faces.max() + 1``.

    Returns
    -------
    (V,) bool
    """
    f = np.asarray(faces, dtype=np.int64)
    n = int(f.max()) + 1 if n_vertices is None else int(n_vertices)
    mask = np.zeros(n, dtype=bool)
    mask[boundary_edges(f).ravel()] = True
    return mask


def thickness_map(
    faces: ArrayLike,
    thickness_mm: float,
    upper_face: ArrayLike | None = None,
    upper_factor: float = 1.0,
    source: str = "mesh",
) -> NDArray[np.float64]:
    """Per-element shell thickness, thicker on the upper face (the paper's stiffening).

    A triangle counts as upper when at least two of its three vertices are flagged.

    Parameters
    ----------
    faces : (F, 3) int
    thickness_mm : float
        Base thickness, mm (paper: 1 mm).
    upper_face : (V,) bool, optional
        Vertices of the upper face (eyes, forehead, nose); None gives a uniform thickness.
    upper_factor : float
        Thickness multiplier on upper triangles (> 0).
    source : str
        Label for error messages.

    Returns
    -------
    (F,) float, mm
    """
    f = np.asarray(faces, dtype=np.int64)
    if not (np.isfinite(thickness_mm) and thickness_mm > 0):
        raise InputError(source, f"thickness_mm: expected a positive number, got {thickness_mm}")
    if not (np.isfinite(upper_factor) and upper_factor > 0):
        raise InputError(source, f"upper_factor: expected a positive number, got {upper_factor}")
    t = np.full(f.shape[0], float(thickness_mm))
    if upper_face is not None:
        up = np.asarray(upper_face)
        if up.ndim != 1 or up.dtype != np.bool_ or up.shape[0] <= f.max():
            raise InputError(
                source,
                f"upper_face: expected a (V,) bool mask with V > {f.max()}, got "
                f"shape {up.shape} dtype {up.dtype}",
            )
        t[up[f].sum(axis=1) >= 2] *= upper_factor
    return t


def assemble(
    vertices: ArrayLike,
    faces: ArrayLike,
    thickness_mm: float | ArrayLike = 1.0,
    material: ShellMaterial | None = None,
    *,
    element: str = "tria3dsg",
    mass: str = "consistent",
    source: str = "mesh",
) -> tuple[sp.csc_matrix, sp.csc_matrix]:
    """Assemble the shell stiffness and mass matrices of a triangle mesh.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int, counter-clockwise
    thickness_mm : float or (F,) float, mm
        Shell thickness, uniform or per element.
    material : ShellMaterial, optional
        Default: steel (E = 210000 MPa, nu = 0.3, rho = 7.85e-9 t/mm^3), plain shell.
    element : {"tria3dsg", "tria3r"}
        pyfe3d triangle: ``Tria3DSG`` (discrete shear gap transverse shear, the default) or
        ``Tria3R`` (one-point transverse shear with a stabilisation factor that depends on
        element length / thickness). On a simply supported 100 mm steel plate 1 mm thick with
        a 24 x 24 mesh, Tria3DSG is within 0.4-1.8 % of plate theory for the first four
        modes and converges under refinement, while Tria3R is 3-5 % stiff and gets worse
        from 16 x 16 to 24 x 24: it locks when elements are a few thicknesses long, which is
        the regime of a face mesh (2-5 mm elements, 1 mm shell).
    mass : {"consistent", "lumped", "vertex"}
        Mass matrix type. The drilling rotation has no inertia in any. ``"vertex"``: the
        shell's total mass shared equally by the vertices (translations only, no rotary
        inertia), so that the mass inner product weighs every vertex alike, as the
        per-vertex RMS of a reconstruction does (the modes then depend on where the mesh is
        dense).
    source : str
        Label for error messages.

    Returns
    -------
    K : (6V, 6V) scipy.sparse.csc_matrix, symmetric, N/mm for translations
    M : (6V, 6V) scipy.sparse.csc_matrix, symmetric positive semi-definite, tonne

    Raises
    ------
    InputError
        Bad mesh (see :func:`check_mesh`), non-positive thickness or material values, a
        thickness array of the wrong shape, or an unknown element / mass type.

    Notes
    -----
    pyfe3d computes element matrices one element object at a time, so the element loop is a
    Python loop over faces calling compiled methods (about 20 us per face, 0.5 s for the
    20,000 faces of a 60,000-DOF model); the sparse assembly itself is vectorised.
    """
    v, f = check_mesh(vertices, faces, source)
    mat = ShellMaterial() if material is None else material
    mat.check(source)
    if element not in _ELEMENTS:
        raise InputError(source, f"element: expected one of {_ELEMENTS}, got {element!r}")
    if mass not in _MASS_TYPES:
        raise InputError(source, f"mass: expected one of {tuple(_MASS_TYPES)}, got {mass!r}")
    t = _thickness(thickness_mm, f.shape[0], source)
    kr, kc, kv, mr, mc, mv = _element_matrices(v, f, t, mat, element, mass)
    n_dof = DOF * v.shape[0]
    if mass == "vertex":
        total = mat.density_t_per_mm3 * float(np.sum(t * face_areas(v, f)))
        used = np.zeros(v.shape[0], dtype=bool)
        used[f.ravel()] = True
        return _symmetric_csc(kr, kc, kv, n_dof), vertex_mass(total, used)
    return _symmetric_csc(kr, kc, kv, n_dof), _symmetric_csc(mr, mc, mv, n_dof)


def _thickness(thickness_mm, n_faces: int, source: str) -> NDArray[np.float64]:
    """(F,) positive thickness from a float or a per-face array, mm."""
    t = np.asarray(thickness_mm, dtype=np.float64)
    if t.ndim == 0:
        t = np.full(n_faces, float(t))
    if t.shape != (n_faces,):
        raise InputError(
            source, f"thickness_mm: expected a float or shape ({n_faces},), got {t.shape}"
        )
    bad = np.flatnonzero(~(np.isfinite(t) & (t > 0)))
    if bad.size:
        raise InputError(
            source, f"thickness_mm: expected positive values, face {bad[0]} has {t[bad[0]]}"
        )
    return t


def _element_matrices(v, f, t, mat: ShellMaterial, element: str, mass: str):
    """COO triplets of every element's stiffness and mass (pyfe3d, one element at a time)."""
    import pyfe3d

    if element == "tria3r":
        data, probe = pyfe3d.Tria3RData(), pyfe3d.Tria3RProbe()
        elem = pyfe3d.Tria3R(probe)
    else:
        data, probe = pyfe3d.Tria3DSGData(), pyfe3d.Tria3DSGProbe()
        elem = pyfe3d.Tria3DSG(probe)
    nk, nm = data.KC0_SPARSE_SIZE, data.M_SPARSE_SIZE
    n_faces = f.shape[0]
    kr = np.zeros(n_faces * nk, dtype=pyfe3d.INT)
    kc = np.zeros(n_faces * nk, dtype=pyfe3d.INT)
    kv = np.zeros(n_faces * nk, dtype=np.float64)
    mr = np.zeros(n_faces * nm, dtype=pyfe3d.INT)
    mc = np.zeros(n_faces * nm, dtype=pyfe3d.INT)
    mv = np.zeros(n_faces * nm, dtype=np.float64)
    values, prop_index = np.unique(t, return_inverse=True)
    props = [_shell_prop(float(h), mat) for h in values]
    x = v.ravel()
    mtype = _MASS_TYPES[mass]
    cols = (DOF * f).tolist()
    pidx = prop_index.ravel().tolist()
    # One element object is reused: its state is fully reset by the attribute writes and the
    # update_* calls below, and pyfe3d writes each element's block at init_k_* offsets.
    for i in range(n_faces):
        elem.c1, elem.c2, elem.c3 = cols[i]
        elem.init_k_KC0 = i * nk
        elem.init_k_M = i * nm
        prop = props[pidx[i]]
        elem.update_rotation_matrix(x)
        elem.update_probe_xe(x)
        elem.update_KC0(kr, kc, kv, prop)
        elem.update_M(mr, mc, mv, prop, mtype)
    if mtype == 1 and element == "tria3r":  # its lumped mass fills 90 entries per element
        used = (np.arange(n_faces * nm) % nm) < 90
        mr, mc, mv = mr[used], mc[used], mv[used]
    return kr, kc, kv, mr, mc, mv


def vertex_mass(total: float, used: NDArray[np.bool_]) -> sp.csc_matrix:
    """A mass shared equally by the translations of the vertices ``used``.

    Parameters
    ----------
    total : float
        Total mass, tonne.
    used : (V,) bool
        Vertices that carry it.

    Returns
    -------
    (6V, 6V) scipy.sparse.csc_matrix, diagonal, tonne (zero on rotations and other vertices)
    """
    n_vertices = used.shape[0]
    diag = np.zeros(DOF * n_vertices)
    for a in range(3):
        diag[a::DOF] = np.where(used, total / used.sum(), 0.0)
    return sp.diags(diag).tocsc()


def membrane_mass(
    vertices: ArrayLike,
    faces: ArrayLike,
    thickness_mm: float | ArrayLike,
    density_t_per_mm3: float,
    mass: str = "consistent",
    source: str = "mesh",
) -> sp.csc_matrix:
    """Mass matrix of a membrane (a shell without stiffness of its own: translations only).

    Linear triangles: the consistent mass ``rho t A / 12`` times ``[[2, 1, 1], [1, 2, 1],
    [1, 1, 2]]`` per axis (what :func:`assemble` gives the translations of a shell without
    rotary inertia), lumped ``rho t A / 3`` per corner, or (``"vertex"``) the total shared
    equally by the vertices (:func:`vertex_mass`).

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int
    thickness_mm : float or (F,) float, mm
    density_t_per_mm3 : float
        rho > 0, tonne/mm^3.
    mass : {"consistent", "lumped", "vertex"}
    source : str
        Label for error messages.

    Returns
    -------
    (6V, 6V) scipy.sparse.csc_matrix, symmetric positive semi-definite, tonne (zero on the
    rotations)
    """
    v, f = check_mesh(vertices, faces, source)
    if mass not in _MASS_TYPES:
        raise InputError(source, f"mass: expected one of {tuple(_MASS_TYPES)}, got {mass!r}")
    rho = float(density_t_per_mm3)
    if not (np.isfinite(rho) and rho > 0):
        raise InputError(source, f"density_t_per_mm3: expected a positive number, got {rho}")
    face_mass = rho * _thickness(thickness_mm, f.shape[0], source) * face_areas(v, f)
    if mass == "vertex":
        used = np.zeros(v.shape[0], dtype=bool)
        used[f.ravel()] = True
        return vertex_mass(float(face_mass.sum()), used)
    if mass == "lumped":
        share = np.zeros(v.shape[0])
        np.add.at(share, f.ravel(), np.repeat(face_mass / 3.0, 3))
        return sp.diags(np.repeat(share, DOF) * np.tile([1.0, 1, 1, 0, 0, 0], v.shape[0])).tocsc()
    i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    pair = np.where(i == j, 2.0, 1.0).ravel() / 12.0  # (9,) corner pairs
    rows = DOF * f[:, i.ravel()][:, :, None] + np.arange(3)  # (F, 9, 3): each axis
    cols = DOF * f[:, j.ravel()][:, :, None] + np.arange(3)
    vals = np.broadcast_to((face_mass[:, None] * pair)[:, :, None], rows.shape)
    return _symmetric_csc(rows.ravel(), cols.ravel(), vals.ravel(), DOF * v.shape[0])


def _shell_prop(thickness: float, mat: ShellMaterial):
    """pyfe3d's isotropic ShellProp with the material's membrane scale and rotary inertia."""
    from pyfe3d.shellprop_utils import isotropic_plate

    prop = isotropic_plate(
        thickness=thickness,
        E=mat.youngs_modulus_mpa,
        nu=mat.poisson_ratio,
        rho=mat.density_t_per_mm3,
    )
    if mat.membrane_scale != 1.0:
        for name in ("A11", "A12", "A16", "A22", "A26", "A66"):
            setattr(prop, name, getattr(prop, name) * mat.membrane_scale)
    if not mat.rotary_inertia:
        prop.intrhoz2 = 0.0
    return prop


def _symmetric_csc(rows, cols, vals, n):
    """Sum COO triplets into a CSC matrix, symmetrised (element matrices are symmetric only
    to round-off). int32 indices make scipy's COO-to-CSR summation about twice as fast; exact
    zeros (the massless rotations' rows of a mass matrix without rotary inertia) are left out."""
    idx = np.int32 if n < np.iinfo(np.int32).max else np.int64
    nonzero = vals != 0.0
    if not nonzero.all():
        rows, cols, vals = rows[nonzero], cols[nonzero], vals[nonzero]
    a = sp.coo_matrix((vals, (rows.astype(idx), cols.astype(idx))), shape=(n, n)).tocsr()
    a = ((a + a.T) * 0.5).tocsc()
    a.sort_indices()
    return a


def fixed_dofs(vertex_mask: ArrayLike, components: str = "all") -> NDArray[np.int64]:
    """Global DOF indices of the given vertices.

    Parameters
    ----------
    vertex_mask : (V,) bool
        Vertices to fix.
    components : {"all", "translations", "rotations"}
        Fix all six DOFs (clamped), only u, v, w (pinned / simply supported) or only the
        rotations (a membrane, which has none).

    Returns
    -------
    (n,) int64, sorted
    """
    comps = {"all": np.arange(DOF), "translations": np.arange(3), "rotations": np.arange(3, DOF)}
    if components not in comps:
        raise InputError(
            "fixed_dofs", f"components: expected one of {tuple(comps)}, got {components!r}"
        )
    idx = np.flatnonzero(np.asarray(vertex_mask, dtype=bool))
    comps = comps[components]
    return (DOF * idx[:, None] + comps[None, :]).ravel().astype(np.int64)
