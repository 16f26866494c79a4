"""The face's natural modal basis: the shell model of the neutral mesh and its lowest modes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from scan2morph.errors import InputError
from scan2morph.modal import fem, skin
from scan2morph.modal.eigen import SolverOptions, solve_modes

#: What the coordinates of a basis are (:attr:`ModalParams.coordinates`).
COORDINATES = ("mass", "vertex")


@dataclass(frozen=True)
class ModalParams:
    """Parameters of the face's modal model (paper defaults where the paper fixes them).

    Parameters
    ----------
    n_modes : int
        Number of modes k.
    thickness_mm : float
        Base shell thickness, mm (paper: 1 mm).
    upper_thickness_factor : float
        Thickness multiplier on the upper face. The paper thickens the upper face so that the
        lowest modes leave it "quite fixed" but gives no value; 3 (the config default) is
        ours. Bending stiffness grows with its cube, mass and membrane stiffness linearly, so
        on a curved shell the effect is milder than the cube suggests: on a 80 x 100 x 30 mm
        cap the upper half's mean share of the six lowest modes' motion is 42 % uniform,
        25 % at 2, 18 % at 3, 11 % at 5 and 6 % at 10.
    material : fem.ShellMaterial
        Steel by default (the paper's choice; it only scales the frequencies). Young's
        modulus 0: no shell at all, a membrane whose stiffness is the skin terms' alone
        (:func:`skin.skin_stiffness`, which must then hold it) on the translations, its mass
        :func:`fem.membrane_mass`; the rotations are held (zero in every vector).
    boundary : {"clamped", "pinned"}
        Fixed vertices held in all six DOFs (paper) or in translation only.
    element : {"tria3dsg", "tria3r"}
        pyfe3d shell triangle; see :func:`fem.assemble`.
    mass : {"consistent", "lumped", "vertex"}
        See :func:`fem.assemble`.
    method : {"block", "arpack", "dense"}
        Eigensolver, see :func:`solve_modes`.
    threads : int
        Threads for the eigensolver's triangular solves.
    seed : int
        Seed of the eigensolver's random start block.
    tension_n_per_mm : float
        Isotropic skin tension ``T``, N/mm (:func:`skin.skin_stiffness`); 0: none.
    foundation_n_per_mm3 : float
        Stiffness of the tissue under the skin against normal motion, N/mm^3; 0: none.
    tether_n_per_mm3 : float
        Tangential tie of the skin to the bone on the tethered vertices, N/mm^3; 0: none.
    tether_normal_n_per_mm3 : float
        The bone's resistance to normal motion on the tethered vertices, added to the
        foundation there, N/mm^3; 0: none.
    mimic_tension_factor : float
        Factor on the tension in the mimic skin (the ``mimic`` weight of :func:`modal_basis`,
        :func:`skin.face_field`): below 1 the skin there is softer, its waves shorter, and the
        lowest modes put more of their motion there. 1: uniform.
    mimic_foundation_factor : float
        The same for the foundation (:func:`skin.vertex_field`).
    mimic_mass_factor : float
        The same for a membrane's mass (its thickness); only without shell.
    clamp_strip_mm : float
        0 (default): the ``fixed`` vertices of :func:`modal_basis` are clamped. > 0: they are
        held instead by the skin beyond the cut, a strip this wide (mm) under the tension
        ``tension_n_per_mm`` held at its far edge (:func:`skin.edge_springs`, on the fixed
        vertices of the mesh's boundary; needs a tension), and move; fixed vertices inside the
        mesh stay clamped.
    coordinates : {"mass", "vertex"}
        The inner product the returned basis is orthonormal in, hence what the coordinates
        ``q = Q^T M v`` (:func:`~scan2morph.modal.project`) are: ``"mass"`` (the paper, Eq. 7)
        the model's mass; ``"vertex"`` every vertex's translation weighted alike
        (:func:`vertex_orthonormal`), so that the first K coordinates are the least squares
        fit of a field's translations on the first K vectors, for every K.
    """

    n_modes: int = 100
    thickness_mm: float = 1.0
    upper_thickness_factor: float = 3.0
    material: fem.ShellMaterial = field(default_factory=fem.ShellMaterial)
    boundary: str = "clamped"
    element: str = "tria3dsg"
    mass: str = "consistent"
    method: str = "block"
    threads: int = 2
    seed: int = 0
    tension_n_per_mm: float = 0.0
    foundation_n_per_mm3: float = 0.0
    tether_n_per_mm3: float = 0.0
    tether_normal_n_per_mm3: float = 0.0
    mimic_tension_factor: float = 1.0
    mimic_foundation_factor: float = 1.0
    mimic_mass_factor: float = 1.0
    clamp_strip_mm: float = 0.0
    coordinates: str = "mass"

    @property
    def has_shell(self) -> bool:
        """Whether the model has a shell (Young's modulus > 0) or is a membrane."""
        return self.material.youngs_modulus_mpa != 0

    @property
    def has_skin(self) -> bool:
        """Whether any skin term (tension, foundation, tether) adds to the shell stiffness."""
        terms = (self.tension_n_per_mm, self.foundation_n_per_mm3, self.tether_n_per_mm3)
        return any(terms) or bool(self.tether_normal_n_per_mm3)


@dataclass(frozen=True)
class ModalBasis:
    """A mass-orthonormal basis of displacement fields of a mesh.

    Attributes
    ----------
    frequencies_hz : (k,) float
        Natural frequency of each vector, Hz; for vectors that are not natural modes
        (semantic, natural modified) the Rayleigh-quotient frequency
        ``sqrt(q^T K q) / (2 pi)``.
    vectors : (6V, k) float
        Full DOF vectors (u, v, w, r_x, r_y, r_z per vertex) as columns,
        ``vectors.T @ mass @ vectors = I``.
    mass : (6V, 6V) scipy.sparse.csc_matrix, tonne
    stiffness : (6V, 6V) scipy.sparse.csc_matrix, N/mm
    thickness_mm : (F,) float
    fixed_vertices : (V,) bool
        Vertices held fixed (boundary, and vertices no face uses).
    names : tuple of str, length k
        ``"mode_001"`` ... for natural modes; the given names for semantic vectors;
        ``"modified_007"`` for natural mode 7 re-orthonormalised against them.
    """

    frequencies_hz: NDArray[np.float64]
    vectors: NDArray[np.float64]
    mass: sp.csc_matrix
    stiffness: sp.csc_matrix
    thickness_mm: NDArray[np.float64]
    fixed_vertices: NDArray[np.bool_]
    names: tuple[str, ...]

    @property
    def n_modes(self) -> int:
        """Number of basis vectors k."""
        return self.vectors.shape[1]

    @property
    def n_vertices(self) -> int:
        """Number of mesh vertices V."""
        return self.vectors.shape[0] // fem.DOF

    @property
    def modes(self) -> NDArray[np.float64]:
        """(k, V, 3) float: translational part of each vector (the store's ``/modal/modes``)."""
        return self.dof_modes[:, :, :3]

    @property
    def dof_modes(self) -> NDArray[np.float64]:
        """(k, V, 6) float: each vector per vertex, translations then rotations."""
        return self.vectors.T.reshape(self.n_modes, self.n_vertices, fem.DOF)


@dataclass(frozen=True)
class Held:
    """How the boundary is held: vertices clamped, and boundary vertices held elastically by
    the skin beyond the cut (:func:`skin.edge_springs`, a strip ``ModalParams.clamp_strip_mm``
    wide) instead.

    Attributes
    ----------
    clamped : (V,) bool
        Vertices clamped.
    sprung : (V,) bool
        Vertices on the mesh's boundary held by the springs (a vertex in both is sprung).
    """

    clamped: NDArray[np.bool_]
    sprung: NDArray[np.bool_]

    def checked_sprung(self, n_vertices: int, boundary: np.ndarray, source: str) -> np.ndarray:
        """``sprung`` after checking both masks' shapes and that it lies on the boundary."""
        for name in ("clamped", "sprung"):
            mask = np.asarray(getattr(self, name))
            if mask.shape != (n_vertices,) or mask.dtype != np.bool_:
                raise InputError(
                    source, f"{name}: expected a ({n_vertices},) bool mask, got {mask.shape}"
                )
        sprung = np.asarray(self.sprung)
        if (sprung & ~boundary).any():
            inner = int(np.flatnonzero(sprung & ~boundary)[0])
            raise InputError(source, f"sprung: vertex {inner} is not on the mesh's boundary")
        return sprung


def modal_basis(
    vertices: ArrayLike,
    faces: ArrayLike,
    params: ModalParams | None = None,
    upper_face: ArrayLike | None = None,
    *,
    fixed: ArrayLike | None = None,
    tethered: ArrayLike | None = None,
    mimic: ArrayLike | None = None,
    source: str = "neutral",
) -> ModalBasis:
    """Natural modal basis of a neutral face mesh (paper Sec. III.B).

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int, counter-clockwise
    params : ModalParams, optional
    upper_face : (V,) bool, optional
        Vertices of the upper face, thickened by ``params.upper_thickness_factor``.
    fixed : (V,) bool or Held, optional
        Vertices held fixed; default every boundary vertex. A :class:`Held` clamps its
        ``clamped`` vertices and holds its ``sprung`` ones elastically (below). A face template
        has two boundary loops, the outline and the mouth: the paper fixes the outline, and the
        lips must stay free (fixing the mouth loop clamps the lips, and no mode can then move
        them). An
        all-False mask leaves the model free: its rigid-body motion, unless a skin term holds
        it, comes first as modes of (numerically) zero frequency. ``params.clamp_strip_mm``
        holds those on the mesh's boundary elastically instead (not in ``fixed_vertices``), or
        only the ``sprung`` ones of a :class:`Held`.
    tethered : (V,) bool, optional
        Vertices whose skin is tied tangentially (``params.tether_n_per_mm3``).
    mimic : (V,) float in [0, 1], optional
        How much each vertex belongs to the mimic skin (:func:`skin.mimic_skin`), where the
        ``params.mimic_*_factor`` apply; None: nowhere.
    source : str
        Label for error messages, e.g. ``"subject/take"``.

    Returns
    -------
    ModalBasis
        ``params.n_modes`` natural modes, ascending in frequency.

    Raises
    ------
    InputError
        A bad mesh, a mesh without boundary, a connected part without boundary vertex,
        non-positive material or thickness values, or more modes than free DOFs.
    """
    p = ModalParams() if params is None else params
    v, f = fem.check_mesh(vertices, faces, source)
    if p.boundary not in ("clamped", "pinned"):
        raise InputError(source, f"boundary: expected 'clamped' or 'pinned', got {p.boundary!r}")
    if p.coordinates not in COORDINATES:
        raise InputError(
            source, f"coordinates: expected one of {COORDINATES}, got {p.coordinates!r}"
        )
    n_v = v.shape[0]
    boundary, sprung, free_model = _held(fixed, f, n_v, source)
    thickness = fem.thickness_map(f, p.thickness_mm, upper_face, p.upper_thickness_factor, source)
    k_mat, m_mat = _matrices(v, f, thickness, p, (tethered, mimic), source)
    if p.clamp_strip_mm and not free_model:  # the skin beyond the cut holds them, elastically
        k_mat, boundary = _strip(v, f, boundary, k_mat, p, source, sprung)
    elif sprung is not None and sprung.any():
        raise InputError(source, "sprung: the skin beyond the cut needs a clamp_strip_mm > 0")
    unused = np.ones(n_v, dtype=bool)
    unused[f.ravel()] = False
    fixed = boundary | unused
    dofs = np.concatenate(
        [
            fem.fixed_dofs(boundary, "all" if p.boundary == "clamped" else "translations"),
            fem.fixed_dofs(unused, "all"),
            fem.fixed_dofs(np.full(n_v, not p.has_shell), "rotations"),
        ]
    )
    freqs, vecs = solve_modes(
        k_mat,
        m_mat,
        dofs,
        p.n_modes,
        SolverOptions(
            method=p.method,
            threads=p.threads,
            seed=p.seed,
            shift=_free_shift(k_mat, m_mat) if free_model else 0.0,
        ),
        source=source,
    )
    names = tuple(f"mode_{i + 1:03d}" for i in range(p.n_modes))
    basis = ModalBasis(freqs, vecs, m_mat, k_mat, thickness, fixed, names)
    return vertex_orthonormal(basis) if p.coordinates == "vertex" else basis


def vertex_orthonormal(basis: ModalBasis) -> ModalBasis:
    """The basis orthonormalised, in its order, in the inner product that weighs every vertex's
    translation alike.

    ``W`` is the model's total mass shared equally by the translations of its vertices
    (:func:`fem.vertex_mass`; rotations weigh nothing; the modes are zero on fixed vertices).
    With ``G = Q^T W Q = R^T R`` (Cholesky, R upper triangular with a positive diagonal) the
    new vectors are ``Q R^-1``:
    vector j is natural vector j plus a combination of the ones before it, so the first K
    vectors span what the first K natural modes span, for every K, and ``q = Q^T W v`` is the
    least squares fit (uniform weight per vertex) of a field's translations on them. On an
    even mesh ``W`` is close to the consistent mass and the vectors close to the natural
    modes; on an uneven one (a scan's mesh) the mass projection weighs big triangles more than
    the per-vertex RMS does.

    Parameters
    ----------
    basis : ModalBasis
        Orthonormal in its ``mass``.

    Returns
    -------
    ModalBasis
        ``mass`` is ``W`` (tonne), ``vectors.T @ W @ vectors = I``; ``frequencies_hz`` the
        Rayleigh quotients ``sqrt(q^T K q) / (2 pi)``; names, stiffness, thickness and fixed
        vertices as given.

    Raises
    ------
    InputError
        The vectors' translations are linearly dependent (``G`` not positive definite).
    """
    x = basis.vectors
    total = float(basis.mass[0 :: fem.DOF, 0 :: fem.DOF].sum())
    w = fem.vertex_mass(total, np.ones(basis.n_vertices, dtype=bool))
    g = x.T @ (w @ x)
    try:
        r = np.linalg.cholesky(0.5 * (g + g.T)).T
    except np.linalg.LinAlgError as exc:
        raise InputError(
            "modal basis",
            "coordinates: 'vertex' needs modes whose translations are independent; these are "
            "not (a mode moves the rotations alone): use 'mass'",
        ) from exc
    y = la.solve_triangular(r, x.T, trans="T", lower=False).T
    freqs = np.sqrt(np.maximum(np.einsum("ij,ij->j", y, basis.stiffness @ y), 0.0))
    return ModalBasis(
        freqs / (2.0 * np.pi),
        y,
        w,
        basis.stiffness,
        basis.thickness_mm,
        basis.fixed_vertices,
        basis.names,
    )


def _matrices(v, f, thickness, p: ModalParams, regions, source: str):
    """Stiffness (shell plus the skin terms, if any; the skin terms alone for a membrane) and
    mass of the model, N/mm and tonne; ``regions``: the tethered mask and the mimic weight."""
    tethered, mimic = regions
    if mimic is not None:
        mimic = np.asarray(mimic, dtype=np.float64)
        if mimic.shape != (len(v),) or not ((mimic >= 0) & (mimic <= 1)).all():
            raise InputError(source, f"mimic: expected ({len(v)},) weights in [0, 1]")
    if p.has_shell and p.mimic_mass_factor != 1.0:
        raise InputError(source, "mimic_mass_factor: only a membrane (no shell) takes it")
    if p.has_shell:
        k_mat, m_mat = fem.assemble(
            v, f, thickness, p.material, element=p.element, mass=p.mass, source=source
        )
    elif not p.has_skin:
        raise InputError(
            source,
            "youngs_modulus_mpa: 0 (no shell) needs the skin's tension, foundation or tether "
            "to hold the membrane; all are 0",
        )
    else:
        thickness = thickness * skin.face_field(1.0, p.mimic_mass_factor, mimic, f, "mass")
        m_mat = fem.membrane_mass(v, f, thickness, p.material.density_t_per_mm3, p.mass, source)
        k_mat = sp.csc_matrix(m_mat.shape)
    if p.has_skin:
        terms = skin.skin_stiffness(
            v,
            f,
            skin.face_field(p.tension_n_per_mm, p.mimic_tension_factor, mimic, f, "tension"),
            skin.vertex_field(
                p.foundation_n_per_mm3, p.mimic_foundation_factor, mimic, "foundation"
            ),
            tethered,
            p.tether_n_per_mm3,
            p.tether_normal_n_per_mm3,
            source,
        )
        k_mat = (k_mat + terms).tocsc()
    return k_mat, m_mat


def _held(fixed, f, n_v: int, source: str):
    """The vertices held (a mask, or a :class:`Held`'s clamped and sprung together; default the
    mesh's boundary), the sprung ones (None without a :class:`Held`) and whether nothing is
    held (a free model), after checking them."""
    boundary = fem.boundary_vertices(f, n_v)
    sprung = None
    if isinstance(fixed, Held):
        sprung = fixed.checked_sprung(n_v, boundary, source)
        fixed = np.asarray(fixed.clamped, dtype=bool) | sprung
    if fixed is not None:
        fixed_mask = np.asarray(fixed, dtype=bool)
        if fixed_mask.shape != (n_v,):
            raise InputError(
                source, f"fixed: expected a ({n_v},) bool mask, got shape {fixed_mask.shape}"
            )
        boundary = fixed_mask
    free_model = fixed is not None and not boundary.any()
    if not boundary.any() and not free_model:
        raise InputError(
            source, "faces: the mesh has no boundary edge (closed surface); nothing to fix"
        )
    if not free_model:
        _check_every_part_held(f, n_v, boundary, source)
    return boundary, sprung, free_model


def _strip(v, f, fixed, k_mat, p: ModalParams, source: str, sprung=None):
    """The stiffness with :func:`skin.edge_springs` (``p.clamp_strip_mm`` > 0) on the fixed
    vertices of the mesh's boundary (those of ``sprung`` only, when given), and the fixed
    vertices left clamped."""
    if not (np.isfinite(p.clamp_strip_mm) and p.clamp_strip_mm > 0):
        raise InputError(source, f"clamp_strip_mm: expected >= 0, got {p.clamp_strip_mm}")
    if not p.tension_n_per_mm > 0:
        raise InputError(source, "clamp_strip_mm: the strip needs a tension_n_per_mm > 0")
    on_cut = fixed & fem.boundary_vertices(f, len(v))
    if sprung is not None:
        on_cut &= sprung
    springs = skin.edge_springs(v, f, on_cut, p.tension_n_per_mm, p.clamp_strip_mm, source)
    return (k_mat + springs).tocsc(), fixed & ~on_cut


def _free_shift(k_mat: sp.spmatrix, m_mat: sp.spmatrix) -> float:
    """A shift for a model held by nothing: 1e-6 of the median translational ``K_ii / M_ii``
    (far below the first elastic eigenvalue, large enough to make ``K + s M`` definite)."""
    dk = k_mat.diagonal()
    dm = m_mat.diagonal()
    trans = np.zeros(dk.size, dtype=bool)
    for a in range(3):
        trans[a :: fem.DOF] = True
    ok = trans & (dm > 0)
    return 1e-6 * float(np.median(dk[ok] / dm[ok]))


def _check_every_part_held(faces, n_vertices, boundary, source):
    """Each connected part of the mesh must contain a boundary vertex, else K is singular."""
    from scipy.sparse.csgraph import connected_components

    e = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    n_comp, label = connected_components(adj, directed=False)
    used = np.zeros(n_vertices, dtype=bool)
    used[faces.ravel()] = True
    held = np.zeros(n_comp, dtype=bool)
    held[label[boundary]] = True
    floating = np.flatnonzero(~held[label] & used)
    if floating.size:
        raise InputError(
            source,
            f"faces: a connected part (containing vertex {floating[0]}) has no boundary "
            "vertex to fix",
        )
