"""Expression coordinates in a modal basis (paper Sec. III.C-D).

An expression is a displacement field ``(V, 3)`` in mm (aligned expression minus neutral). As a
DOF vector it has its translations in ``u, v, w`` and zero rotations. Its coordinates in a
mass-orthonormal basis ``Q`` are the M inner products ``q = Q^T M v`` (paper Eq. 7), so that
``Q q`` is the M-orthogonal projection of ``v`` onto the span of the basis.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scan2morph.errors import InputError
from scan2morph.modal import fem
from scan2morph.modal.basis import ModalBasis

#: Relative M-norm below which a vector is numerically dependent on the ones before it.
DEPENDENCE_TOL = 1e-8


def displacement_dofs(basis: ModalBasis, field: ArrayLike, source: str = "expression"):
    """Displacement field(s) as DOF vectors.

    Parameters
    ----------
    basis : ModalBasis
    field : (V, 3) or (N, V, 3) float, mm; or (V, 6) / (N, V, 6)
        Translations (the rotations are set to zero), or full DOF vectors per vertex
        (translations in mm, then rotations in rad).
    source : str
        Label for error messages.

    Returns
    -------
    (6V,) or (6V, N) float
    """
    f = np.asarray(field, dtype=np.float64)
    n_v = basis.n_vertices
    if f.ndim not in (2, 3) or f.shape[-2] != n_v or f.shape[-1] not in (3, fem.DOF):
        raise InputError(
            source,
            f"displacement: expected shape ({n_v}, 3), ({n_v}, 6) or (N, {n_v}, 3|6), "
            f"got {f.shape}",
        )
    if not np.all(np.isfinite(f)):
        raise InputError(source, "displacement: expected finite values, found NaN or inf")
    many = f.reshape(-1, n_v, f.shape[-1])
    out = np.zeros((many.shape[0], n_v, fem.DOF))
    out[:, :, : f.shape[-1]] = many
    out = out.reshape(many.shape[0], -1).T
    return out[:, 0] if f.ndim == 2 else out


def project(basis: ModalBasis, field: ArrayLike, source: str = "expression") -> NDArray:
    """Modal coordinates of a displacement field, ``q = Q^T M v`` (paper Eq. 7).

    Parameters
    ----------
    basis : ModalBasis
    field : (V, 3) or (N, V, 3) float, mm
        Translations (rotations zero); (V, 6) full DOF vectors are accepted too.
    source : str
        Label for error messages.

    Returns
    -------
    (k,) or (N, k) float
        Coordinates, mm * sqrt(tonne) (the basis vectors have unit M norm).
    """
    v = displacement_dofs(basis, field, source)
    return (basis.vectors.T @ (basis.mass @ v)).T


def reconstruct(basis: ModalBasis, coords: ArrayLike, n_modes: int | None = None) -> NDArray:
    """Displacement field from the first ``n_modes`` modal coordinates.

    Parameters
    ----------
    basis : ModalBasis
    coords : (k,) float
        Coordinates from :func:`project`.
    n_modes : int, optional
        Number K of leading coordinates to use; default all.

    Returns
    -------
    (V, 3) float, mm
        Translational part of ``Q[:, :K] @ q[:K]``.
    """
    q = np.asarray(coords, dtype=np.float64)
    if q.shape != (basis.n_modes,):
        raise InputError("coordinates", f"expected shape ({basis.n_modes},), got {q.shape}")
    kk = basis.n_modes if n_modes is None else int(n_modes)
    if not 0 <= kk <= basis.n_modes:
        raise InputError("coordinates", f"n_modes: expected 0..{basis.n_modes}, got {n_modes}")
    full = basis.vectors[:, :kk] @ q[:kk]
    return full.reshape(-1, fem.DOF)[:, :3].copy()


def reconstruction_error_curve(
    basis: ModalBasis,
    field: ArrayLike,
    ks: Sequence[int],
    *,
    weighting: str = "mass",
    source: str = "expression",
) -> NDArray[np.float64]:
    """RMS error of the reconstruction from the first K modes, for each K in ``ks``.

    Parameters
    ----------
    basis : ModalBasis
    field : (V, 3) float, mm (or (V, 6) full DOF)
    ks : sequence of int
        Numbers of leading modes, each in 0..k.
    weighting : {"mass", "vertex"}
        ``"mass"``: ``sqrt(e^T M e / m)`` with ``e`` the DOF residual (rotations included) and
        ``m`` the total mass, the norm the projection minimises, so the curve never increases
        with K. ``"vertex"``: plain RMS over vertices of the translation error length (not
        guaranteed monotone: the projection is optimal in the M norm, not this one).
    source : str
        Label for error messages.

    Returns
    -------
    (len(ks),) float, mm
    """
    if weighting not in ("mass", "vertex"):
        raise InputError(source, f"weighting: expected 'mass' or 'vertex', got {weighting!r}")
    ks_arr = np.asarray(ks)
    if ks_arr.ndim != 1 or not np.issubdtype(ks_arr.dtype, np.integer):
        raise InputError(source, "ks: expected a 1-D sequence of integers")
    if ks_arr.size and (ks_arr.min() < 0 or ks_arr.max() > basis.n_modes):
        raise InputError(source, f"ks: expected values in 0..{basis.n_modes}")
    v = displacement_dofs(basis, field, source)
    if v.ndim != 1:
        raise InputError(source, "displacement: expected one field (V, 3), not a stack")
    q = basis.vectors.T @ (basis.mass @ v)
    total_mass = float(basis.mass[0 :: fem.DOF, 0 :: fem.DOF].sum())
    out = np.empty(ks_arr.size)
    for i, kk in enumerate(ks_arr):
        e = v - basis.vectors[:, :kk] @ q[:kk]
        if weighting == "mass":
            out[i] = np.sqrt(max(float(e @ (basis.mass @ e)), 0.0) / total_mass)
        else:
            out[i] = np.sqrt(np.mean(np.sum(e.reshape(-1, fem.DOF)[:, :3] ** 2, axis=1)))
    return out


@dataclass(frozen=True)
class ReconstructionSplit:
    """RMS error of an expression rebuilt from its first K modes, split along the surface.

    Attributes
    ----------
    ks : (R,) int
        Numbers of leading modes.
    total_mm, normal_mm, tangential_mm : (R,) float
        RMS over all vertices of the translation error's length, of its component along the
        neutral's vertex normal, and of its part tangent to the surface (sliding), mm;
        ``total_mm**2 = normal_mm**2 + tangential_mm**2``.
    modes_to_target : float
        Smallest K (0 .. k) whose ``total`` error is at most the target: 0 for an expression
        that moves the face less than the target (no mode is needed), NaN when no K reaches it.
    """

    ks: NDArray[np.int64]
    total_mm: NDArray[np.float64]
    normal_mm: NDArray[np.float64]
    tangential_mm: NDArray[np.float64]
    modes_to_target: float


def reconstruction_split(
    basis: ModalBasis,
    field: ArrayLike,
    normals: ArrayLike,
    ks: Sequence[int],
    target_mm: float = 0.5,
    source: str = "expression",
) -> ReconstructionSplit:
    """Reconstruction error against the number of modes, in normal and tangential parts.

    A shell's low modes bend it: they move the surface along its normal. A displacement that
    slides the skin along the surface (tangential) needs the far stiffer membrane modes, so its
    error falls slowly with K; the split says which of the two a residual is.

    Parameters
    ----------
    basis : ModalBasis
    field : (V, 3) float, mm
        The displacement field.
    normals : (V, 3) float
        Unit vertex normals of the neutral mesh (a vertex without one: NaN row; its error
        counts as tangential).
    ks : sequence of int
        Numbers of leading modes, each in 0..k.
    target_mm : float
        RMS error (all vertices, mm) for :attr:`ReconstructionSplit.modes_to_target`.
    source : str
        Label for error messages.

    Returns
    -------
    ReconstructionSplit
    """
    ks_arr = np.asarray(ks)
    if ks_arr.ndim != 1 or not np.issubdtype(ks_arr.dtype, np.integer):
        raise InputError(source, "ks: expected a 1-D sequence of integers")
    if ks_arr.size and (ks_arr.min() < 0 or ks_arr.max() > basis.n_modes):
        raise InputError(source, f"ks: expected values in 0..{basis.n_modes}")
    n = np.asarray(normals, dtype=np.float64)
    if n.shape != (basis.n_vertices, 3):
        raise InputError(source, f"normals: expected shape ({basis.n_vertices}, 3), got {n.shape}")
    n = np.where(np.isfinite(n).all(axis=1, keepdims=True), n, 0.0)
    v = displacement_dofs(basis, field, source)
    if v.ndim != 1:
        raise InputError(source, "displacement: expected one field (V, 3), not a stack")
    q = basis.vectors.T @ (basis.mass @ v)
    # error after K modes for every K = 0 .. k, one mode at a time
    e = v.reshape(-1, fem.DOF)[:, :3].copy()
    modes = basis.vectors.reshape(basis.n_vertices, fem.DOF, basis.n_modes)[:, :3, :]
    total, normal, tangential = (np.empty(basis.n_modes + 1) for _ in range(3))
    for kk in range(basis.n_modes + 1):
        if kk:
            e -= modes[:, :, kk - 1] * q[kk - 1]
        along = np.einsum("vd,vd->v", e, n)
        total[kk] = np.sqrt(np.mean(np.sum(e**2, axis=1)))
        normal[kk] = np.sqrt(np.mean(along**2))
        tangential[kk] = np.sqrt(np.mean(np.sum((e - along[:, None] * n) ** 2, axis=1)))
    reached = np.flatnonzero(total <= target_mm)  # K = 0: the expression is within it already
    return ReconstructionSplit(
        ks_arr.astype(np.int64),
        total[ks_arr],
        normal[ks_arr],
        tangential[ks_arr],
        float(reached[0]) if reached.size else float("nan"),
    )


def semantic_basis(
    basis: ModalBasis,
    expression_fields: Sequence[ArrayLike],
    names: Sequence[str],
    *,
    n_modes: int | None = None,
    source: str = "semantic basis",
) -> ModalBasis:
    """Insert expression vectors at the head of a modal basis (paper Sec. III.D).

    The expression fields become the first ("semantic") vectors, M-normalised and
    Gram-Schmidt-orthonormalised among themselves in their given order; the natural modes
    follow, M-orthogonalised against them and among themselves in frequency order ("natural
    modified" modes); a mode that becomes numerically dependent (relative M norm below
    :data:`DEPENDENCE_TOL`) is dropped.

    Parameters
    ----------
    basis : ModalBasis
        The natural basis.
    expression_fields : sequence of (V, 3) float, mm
        Displacement fields of the identified expressions (not zeroed on the fixed boundary,
        so that each is reproduced exactly by its own vector); (V, 6) full DOF fields are
        accepted too.
    names : sequence of str
        One name per field (e.g. the expression labels).
    n_modes : int, optional
        Total number of vectors to keep; default the size of ``basis``.
    source : str
        Label for error messages.

    Returns
    -------
    ModalBasis
        M-orthonormal; ``names`` gives the semantic names then ``"modified_###"`` (the natural
        mode number); ``frequencies_hz`` are Rayleigh-quotient frequencies.

    Raises
    ------
    InputError
        Names not matching the fields, a field of the wrong shape or of zero M norm, or a
        field dependent on the fields before it.
    """
    fields = list(expression_fields)
    names = [str(n) for n in names]
    if len(fields) != len(names) or not fields:
        raise InputError(
            source, f"names: expected one name per field, got {len(names)} for {len(fields)}"
        )
    if len(set(names)) != len(names):
        raise InputError(source, f"names: expected distinct names, got {names}")
    total = basis.n_modes if n_modes is None else int(n_modes)
    if not len(fields) <= total:
        raise InputError(source, f"n_modes: expected at least {len(fields)}, got {total}")
    m = basis.mass
    e = displacement_dofs(basis, np.stack([np.asarray(f, dtype=np.float64) for f in fields]))
    cols = np.empty((e.shape[0], total))
    r = 0
    for j, name in enumerate(names):
        vec, rel = _orthogonalise(e[:, j], cols[:, :r], m)
        if rel is None:
            raise InputError(source, f"expression {name!r}: displacement has zero mass norm")
        if rel < DEPENDENCE_TOL:
            raise InputError(
                source, f"expression {name!r}: linearly dependent on the expressions before it"
            )
        cols[:, r] = vec
        r += 1
    kept_names = list(names)
    for i in range(basis.n_modes):
        if r >= total:
            break
        vec, rel = _orthogonalise(basis.vectors[:, i], cols[:, :r], m)
        if rel is None or rel < DEPENDENCE_TOL:
            continue
        cols[:, r] = vec
        r += 1
        kept_names.append(f"modified_{i + 1:03d}")
    kept = cols[:, :r] if r == total else cols[:, :r].copy()
    freqs = np.sqrt(np.maximum(np.einsum("ij,ij->j", kept, basis.stiffness @ kept), 0.0))
    return ModalBasis(
        frequencies_hz=freqs / (2.0 * np.pi),
        vectors=kept,
        mass=basis.mass,
        stiffness=basis.stiffness,
        thickness_mm=basis.thickness_mm,
        fixed_vertices=basis.fixed_vertices,
        names=tuple(kept_names),
    )


def _orthogonalise(x, cols, m):
    """M-orthogonalise ``x`` against M-orthonormal ``cols`` twice and M-normalise it.

    Returns the unit vector and its norm relative to the input (None when ``x`` has no M norm).
    """
    norm0 = np.sqrt(max(float(x @ (m @ x)), 0.0))
    if norm0 == 0.0:
        return x, None
    y = x / norm0
    for _ in range(2):
        if cols.shape[1]:
            y = y - cols @ (cols.T @ (m @ y))
    rel = np.sqrt(max(float(y @ (m @ y)), 0.0))
    return (y / rel if rel > 0 else y), rel


@dataclass(frozen=True)
class CoordinateStats:
    """Statistics of the modal coordinates of the repeats of one expression label.

    Attributes
    ----------
    label : str
    takes : tuple of str
        The takes pooled, sorted.
    mean : (k,) float
    std : (k,) float
        Sample standard deviation (ddof = 1); NaN when there is a single take.
    """

    label: str
    takes: tuple[str, ...]
    mean: NDArray[np.float64]
    std: NDArray[np.float64]

    @property
    def n(self) -> int:
        """Number of takes."""
        return len(self.takes)


def coordinate_statistics(
    coords: Mapping[str, ArrayLike], labels: Mapping[str, str], source: str = "coordinates"
) -> dict[str, CoordinateStats]:
    """Mean and standard deviation of modal coordinates per expression label (Sec. III.C.3).

    Parameters
    ----------
    coords : mapping take -> (k,) float
    labels : mapping take -> label
        Must name every take of ``coords``.
    source : str
        Label for error messages.

    Returns
    -------
    dict label -> CoordinateStats, labels sorted
    """
    if not coords:
        raise InputError(source, "coordinates: expected at least one take")
    missing = sorted(set(coords) - set(labels))
    if missing:
        raise InputError(source, f"labels: no label for take(s) {missing}")
    arrays = {t: np.asarray(c, dtype=np.float64) for t, c in coords.items()}
    shapes = {a.shape for a in arrays.values()}
    if len(shapes) != 1 or next(iter(shapes)) == () or len(next(iter(shapes))) != 1:
        raise InputError(source, f"coordinates: expected (k,) arrays of one length, got {shapes}")
    out = {}
    for label in sorted(set(labels[t] for t in arrays)):
        takes = tuple(sorted(t for t in arrays if labels[t] == label))
        x = np.stack([arrays[t] for t in takes])
        std = x.std(axis=0, ddof=1) if len(takes) >= 2 else np.full(x.shape[1], np.nan)
        out[label] = CoordinateStats(label, takes, x.mean(axis=0), std)
    return out
