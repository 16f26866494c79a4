"""How much of a displacement field a basis spans: least squares on the first K basis fields.

Two kinds of bases are compared on the same fields: the modal basis's translational parts, and the
anchor any reviewer tries first, the smooth intrinsic basis of the same mesh (the lowest
eigenfunctions of its cotangent Laplace-Beltrami operator with a free (Neumann) boundary, used
per axis: each function moves the face along x, along y and along z, so ``n`` functions make
``3 n`` fields). :func:`span_curve` fits a field on the first K fields of a basis by least squares
(uniform weight per vertex over the chosen vertices) and splits the residual as the modal stage
does (normal / tangential to the neutral surface, and without the outline);
:func:`residual_split` measures the same parts of any residual, e.g. of the modal stage's own
reconstruction ``Q q``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.typing import ArrayLike, NDArray

from scan2morph.errors import InputError
from scan2morph.modal import skin

#: Share of a basis field's norm below which what it adds to the ones before it counts as nothing.
RANK_TOL = 1e-8


def laplace_beltrami(
    vertices: ArrayLike, faces: ArrayLike, n: int, source: str = "mesh"
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lowest eigenpairs of the Laplace-Beltrami operator, free (Neumann) boundary.

    Solves ``L phi = lambda A phi`` (:func:`~scan2morph.modal.skin.cotangent_laplacian`, ``A`` the lumped
    areas) by
    shift-invert just below zero, so the constant function (lambda = 0) comes first.

    Parameters
    ----------
    vertices : (V, 3) float, mm
    faces : (F, 3) int
    n : int
        Number of functions, 1 <= n < V - 1.
    source : str
        Label for error messages.

    Returns
    -------
    eigenvalues : (n,) float, 1/mm^2, ascending
    functions : (V, n) float
        Area-orthonormal: ``functions.T @ diag(area) @ functions = I``.
    """
    lap, area = skin.cotangent_laplacian(vertices, faces, source)
    n_v = lap.shape[0]
    if not (isinstance(n, int | np.integer) and 1 <= n < n_v - 1):
        raise InputError(source, f"n: expected an integer in [1, {n_v - 2}], got {n}")
    mass = sp.diags(area).tocsc()
    shift = -1e-6 * float(lap.diagonal().mean() / area.mean())
    v0 = np.random.default_rng(0).standard_normal(n_v)
    lam, phi = sla.eigsh(lap.tocsc(), k=int(n), M=mass, sigma=shift, which="LM", v0=v0)
    order = np.argsort(lam)
    return lam[order], phi[:, order]


def per_axis_fields(functions: ArrayLike) -> NDArray[np.float64]:
    """Vector fields from scalar functions, each used along x, y and z.

    Parameters
    ----------
    functions : (V, n) float

    Returns
    -------
    (3 n, V, 3) float
        Field ``3 i + a`` is function ``i`` along axis ``a``; the first ``3 m`` fields are
        the first ``m`` functions per axis.
    """
    phi = np.asarray(functions, dtype=np.float64)
    n_v, n = phi.shape
    out = np.zeros((n, 3, n_v, 3))
    for a in range(3):
        out[:, a, :, a] = phi.T
    return out.reshape(3 * n, n_v, 3)


@dataclass(frozen=True)
class SpanCurve:
    """RMS of what is left of a displacement field after the first K basis fields, mm.

    Attributes
    ----------
    ks : (R,) int
    total_mm : (R,) float
        RMS over the chosen vertices (outline included) of the residual's length.
    normal_mm, tangential_mm : (R,) float
        Of its component along the neutral's vertex normal and of its part along the surface.
    inner_mm : (R,) float
        ``total`` without the outline vertices.
    field_mm : float
        RMS of the field itself over the chosen vertices (``total`` at K = 0).
    """

    ks: NDArray[np.int64]
    total_mm: NDArray[np.float64]
    normal_mm: NDArray[np.float64]
    tangential_mm: NDArray[np.float64]
    inner_mm: NDArray[np.float64]
    field_mm: float

    @property
    def left(self) -> NDArray[np.float64]:
        """(R,) float: ``total_mm / field_mm``, the share of the field's RMS left."""
        return self.total_mm / self.field_mm


def residual_split(
    residual: ArrayLike, normals: ArrayLike, where: ArrayLike, outline: ArrayLike
) -> tuple[float, float, float, float]:
    """RMS of a residual field: total, normal, tangential and without the outline, mm.

    Parameters
    ----------
    residual : (V, 3) float, mm
    normals : (V, 3) float
        Unit normals of the neutral (a non-finite row counts as no normal: all tangential).
    where : (V,) bool
        Vertices measured.
    outline : (V,) bool
        Outline vertices (left out of the fourth value).

    Returns
    -------
    total, normal, tangential, inner : float, mm
    """
    e = np.asarray(residual, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    n = np.where(np.isfinite(n).all(axis=1, keepdims=True), n, 0.0)
    w = np.asarray(where, dtype=bool)
    inner = w & ~np.asarray(outline, dtype=bool)
    along = np.einsum("vd,vd->v", e, n)
    sq = np.sum(e**2, axis=1)

    def rms(x, m):
        return float(np.sqrt(np.mean(x[m]))) if m.any() else float("nan")

    return rms(sq, w), rms(along**2, w), rms(sq - along**2, w), rms(sq, inner)


def span_curve(
    basis_fields: ArrayLike,
    field: ArrayLike,
    ks: Sequence[int],
    normals: ArrayLike,
    where: ArrayLike | None = None,
    outline: ArrayLike | None = None,
    source: str = "span",
) -> SpanCurve:
    """Least squares of a field on the first K basis fields, for each K, and what it leaves.

    One Gram-Schmidt pass over the basis (restricted to the vertices ``where``, each field
    orthogonalised twice against the kept ones) gives the fits on every leading subset at once.
    A basis field that adds nothing new to the ones before it (zero on the chosen vertices, or
    dependent: less than :data:`RANK_TOL` of its norm left) is skipped.

    Parameters
    ----------
    basis_fields : (k, V, 3) float
        Basis fields in order (e.g. :attr:`ModalBasis.modes`, or :func:`per_axis_fields`).
    field : (V, 3) float, mm
        The displacement field.
    ks : sequence of int
        Numbers of leading fields, each in 0..k.
    normals : (V, 3) float
        Unit vertex normals of the neutral.
    where : (V,) bool, optional
        Vertices fitted and measured (default all with a finite field value).
    outline : (V,) bool, optional
        Outline vertices (default none).
    source : str
        Label for error messages.

    Returns
    -------
    SpanCurve
    """
    q = np.asarray(basis_fields, dtype=np.float64)
    v = np.asarray(field, dtype=np.float64)
    if q.ndim != 3 or q.shape[2] != 3 or v.shape != q.shape[1:]:
        raise InputError(
            source, f"expected basis (k, V, 3) and field (V, 3), got {q.shape} and {v.shape}"
        )
    ks_arr = np.asarray(ks, dtype=np.int64)
    if ks_arr.ndim != 1 or (ks_arr.size and (ks_arr.min() < 0 or ks_arr.max() > q.shape[0])):
        raise InputError(source, f"ks: expected integers in 0..{q.shape[0]}")
    finite = np.isfinite(v).all(axis=1)
    w = finite if where is None else np.asarray(where, dtype=bool) & finite
    rim = np.zeros(len(v), bool) if outline is None else np.asarray(outline, dtype=bool)
    a = q[:, w].reshape(q.shape[0], 3 * int(w.sum())).T
    b = v[w].ravel()
    qq, c = _orthonormal_prefix(a), np.zeros(q.shape[0])
    useful = np.any(qq != 0.0, axis=0)
    c[useful] = qq[:, useful].T @ b
    out = np.empty((4, ks_arr.size))
    e = np.zeros_like(v)
    for i, kk in enumerate(ks_arr):
        e[w] = (b - qq[:, :kk] @ c[:kk]).reshape(-1, 3)
        out[:, i] = residual_split(e, normals, w, rim)
    field_rms = residual_split(np.where(w[:, None], v, 0.0), normals, w, rim)[0]
    return SpanCurve(ks_arr, *out, field_mm=field_rms)


def _orthonormal_prefix(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Columns ``j`` orthonormal and spanning, with the columns before them, ``a[:, :j + 1]``;
    a column that adds less than :data:`RANK_TOL` of its norm is zero."""
    out = np.zeros_like(a)
    kept = []
    for j in range(a.shape[1]):
        x = a[:, j].copy()
        norm0 = float(np.linalg.norm(x))
        for _ in range(2):
            if kept:
                x -= out[:, kept] @ (out[:, kept].T @ x)
        norm = float(np.linalg.norm(x))
        if norm0 > 0 and norm > RANK_TOL * norm0:
            out[:, j] = x / norm
            kept.append(j)
    return out
