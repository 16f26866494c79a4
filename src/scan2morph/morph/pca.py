"""Morphing by PCA (Yano-Harada, section 5.2, Eq. 2, Tables 1-3).

The M aligned shapes :math:`S_j` (each a 3V vector) are centred on their mean
:math:`\\bar S`, giving :math:`X' = [S'_0 \\dots S'_{M-1}]` (3V x M). The paper's covariance
is :math:`C = X'X'^T` **without** a 1/M factor, so eigenvalue :math:`\\lambda_i` equals the sum
over the shapes of the squared coefficient :math:`\\omega_i` (its Tables 1 and 2 satisfy this).
C is 3V x 3V and never formed: the eigenpairs :math:`(\\mu_i, \\hat e_i)` of the small M x M
Gram matrix :math:`D = X'^T X'` give :math:`\\lambda_i = \\mu_i` and
:math:`e_i = X'\\hat e_i / \\lVert X'\\hat e_i \\rVert`.

Centring removes one degree of freedom, so there are at most M - 1 components; eigenvalues
below ``EIGEN_RTOL`` times the largest are dropped. Each component's sign is fixed so that its
largest-magnitude entry (as a 3V vector, first one on ties) is positive.

A novel face is :math:`S = \\bar S + \\sum_i \\alpha_i \\sigma_i\\, e_i` with
:math:`-3 \\le \\alpha_i \\le 3` (Eq. 2). The paper writes :math:`\\sigma_i = \\sqrt{\\lambda_i}`;
with its unnormalised C that is :math:`\\sqrt{M}` times the population standard deviation of
:math:`\\omega_i` (:math:`\\sqrt{M - 1}` times the sample one), so its +-3 sigma faces lie far
outside the shapes the model was built from and self-intersect. The **sigma convention**
(:data:`SIGMA_CONVENTIONS`) chooses :math:`\\sigma_i`: ``"sample"`` (the default) is the sample
standard deviation of the coefficients, ``std(omega_i, ddof=1) = sqrt(lambda_i / (M - 1))``;
``"paper"`` is :math:`\\sqrt{\\lambda_i}`. Eigenvalues, CR and CCR are the paper's either way
(Table 1).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import check_vertex_array

#: Eigenvalues below this fraction of the largest are numerical zeros (dropped).
EIGEN_RTOL = 1e-12
#: Shapes whose centred RMS spread is below this fraction of their RMS coordinate are identical.
SPREAD_RTOL = 1e-12
#: Eq. 2's bound on the blending parameters: -ALPHA_LIMIT <= alpha_i <= ALPHA_LIMIT.
ALPHA_LIMIT = 3.0
#: The unit sigma_i of Eq. 2's alphas: name -> what it is (config ``morph.sigma``).
SIGMA_CONVENTIONS = {
    "sample": "sample standard deviation of the coefficients, sqrt(eigenvalue / (M - 1))",
    "paper": "sqrt(eigenvalue) of C = X'X'^T (no 1/M), as printed in the paper",
}

#: The paper's Table 3: name -> (alpha_1, alpha_2, alpha_3) of Eq. 2 (Fig. 16).
DEFAULT_PCA_BLENDS: dict[str, tuple[float, ...]] = {
    "pca_blend1": (0.5, 1.0, 0.0),
    "pca_blend2": (1.0, 0.0, -2.0),
    "pca_blend3": (-0.5, -0.9, 0.9),
}


@dataclass(frozen=True, eq=False)
class PCAModel:
    """A PCA morphable model (arrays are read-only).

    Attributes
    ----------
    mean : (V, 3) float64, mm
        The average shape :math:`\\bar S`.
    components : (K, V, 3) float64
        The principal shapes :math:`e_i`, unit norm as 3V vectors, mutually orthogonal, sorted by
        decreasing eigenvalue; sign: largest-magnitude entry positive.
    eigenvalues : (K,) float64, mm^2
        :math:`\\lambda_i` of :math:`C = X'X'^T` (no 1/M): ``sum(coefficients[:, i]**2)``.
    cr, ccr : (K,) float64
        Contribution rate and cumulative contribution rate (Table 1); ``ccr[-1] == 1``.
    coefficients : (M, K) float64, mm
        :math:`\\omega` of each input shape (Table 2): ``components . (S_j - mean)``.
    names : tuple of str, length M
        Names of the input shapes, in input order.
    sigma : (K,) float64, mm
        The unit of Eq. 2's alphas per component (:data:`SIGMA_CONVENTIONS`); ``None`` when
        constructing: computed from the coefficients and ``sigma_convention``.
    sigma_convention : str
        ``"sample"`` (default) or ``"paper"``.
    """

    mean: np.ndarray
    components: np.ndarray
    eigenvalues: np.ndarray
    cr: np.ndarray
    ccr: np.ndarray
    coefficients: np.ndarray
    names: tuple[str, ...]
    sigma: np.ndarray | None = None
    sigma_convention: str = "sample"

    def __post_init__(self):
        if self.sigma is None:
            object.__setattr__(
                self,
                "sigma",
                sigmas(self.eigenvalues, self.coefficients, self.sigma_convention),
            )
        for field in ("mean", "components", "eigenvalues", "cr", "ccr", "coefficients", "sigma"):
            arr = np.array(getattr(self, field), dtype=np.float64)
            arr.flags.writeable = False
            object.__setattr__(self, field, arr)
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))

    @property
    def n_components(self) -> int:
        """K, the number of principal components."""
        return int(self.eigenvalues.shape[0])


def sigmas(eigenvalues, coefficients, convention: str = "sample", *, source: str = "pca"):
    """The unit sigma_i of Eq. 2's alphas (:data:`SIGMA_CONVENTIONS`).

    Parameters
    ----------
    eigenvalues : (K,) float, mm^2
        Of the paper's C = X'X'^T (no 1/M).
    coefficients : (M, K) float, mm
        The coefficients of the M input shapes (centred: each column sums to zero).
    convention : ``"sample"`` or ``"paper"``
        ``sample``: ``std(coefficients, axis=0, ddof=1)``; ``paper``: ``sqrt(eigenvalues)``.

    Returns
    -------
    (K,) float64, mm
    """
    _check_convention(convention, source)
    if convention == "paper":
        return np.sqrt(np.asarray(eigenvalues, dtype=np.float64))
    return np.std(np.asarray(coefficients, dtype=np.float64), axis=0, ddof=1)


def _check_convention(convention: str, source: str) -> None:
    if convention not in SIGMA_CONVENTIONS:
        raise InputError(
            source,
            f"morph.sigma: {convention!r} unknown (expected one of {sorted(SIGMA_CONVENTIONS)})",
        )


def contribution_rates(eigenvalues, *, source: str = "pca") -> tuple[np.ndarray, np.ndarray]:
    """Contribution rate and cumulative contribution rate of each eigenvalue (Table 1).

    Parameters
    ----------
    eigenvalues : (K,) float
        Eigenvalues, non-negative, in the order the rates are wanted (normally decreasing).
    source : str
        Label used in error messages.

    Returns
    -------
    cr : (K,) float64
        :math:`\\lambda_l / \\sum_j \\lambda_j`.
    ccr : (K,) float64
        :math:`\\sum_{i \\le l} \\lambda_i / \\sum_j \\lambda_j`; the last entry is exactly 1.

    Raises
    ------
    InputError
        If the eigenvalues are not a non-empty 1-D finite non-negative array with a positive sum.
    """
    lam = np.asarray(eigenvalues, dtype=np.float64)
    if lam.ndim != 1 or lam.size == 0:
        raise InputError(source, f"eigenvalues: expected a non-empty (K,) array, got {lam.shape}")
    if not np.isfinite(lam).all() or (lam < 0).any():
        raise InputError(source, f"eigenvalues: expected finite non-negative values, got {lam}")
    cumulative = np.cumsum(lam)
    total = cumulative[-1]
    if total <= 0:
        raise InputError(source, "eigenvalues: all zero, contribution rates are undefined")
    return lam / total, cumulative / total


def _stack_shapes(shapes, names, source: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """Validate the input shapes; return them as (M, V, 3) float64 with their names."""
    if isinstance(shapes, Mapping):
        if names is not None:
            raise InputError(source, "names: give names either as mapping keys or names=, not both")
        names = [str(k) for k in shapes]
        shapes = list(shapes.values())
    if isinstance(shapes, np.ndarray):
        items = list(shapes) if shapes.ndim == 3 else None
        if items is None:
            raise InputError(
                source, f"shapes: expected an (M, V, 3) array, got shape {shapes.shape}"
            )
    elif isinstance(shapes, Sequence):
        items = list(shapes)
    else:
        raise InputError(
            source,
            f"shapes: expected an (M, V, 3) array or a list of (V, 3) arrays, "
            f"got {type(shapes).__name__}",
        )
    m = len(items)
    if names is None:
        names = [str(j) for j in range(m)]
    names = tuple(str(n) for n in names)
    if len(names) != m:
        raise InputError(source, f"names: expected {m} names (one per shape), got {len(names)}")
    if m < 2:
        raise InputError(source, f"shapes: PCA needs at least two shapes, got {m}")
    arrays = []
    for j, (name, item) in enumerate(zip(names, items, strict=True)):
        label = f"shapes[{j}] ({name!r})"
        arr = np.asarray(item, dtype=np.float64)
        if arrays and arr.ndim == 2 and arr.shape[0] != arrays[0].shape[0]:
            raise InputError(
                source,
                f"{label}: has {arr.shape[0]} vertices, expected {arrays[0].shape[0]} "
                f"(as shapes[0] ({names[0]!r}))",
            )
        arrays.append(check_vertex_array(arr, label, source, hint="; fill them before PCA"))
    if arrays[0].shape[0] == 0:
        raise InputError(source, "shapes: have no vertices")
    return np.stack(arrays), names


def _fix_signs(components: np.ndarray) -> np.ndarray:
    """Flip each row of (K, N) so that its largest-magnitude entry (first on ties) is positive."""
    k = np.arange(components.shape[0])
    pivot = components[k, np.argmax(np.abs(components), axis=1)]
    return components * np.where(pivot < 0, -1.0, 1.0)[:, None]


def pca(
    shapes,
    names: Sequence[str] | None = None,
    *,
    sigma: str = "sample",
    source: str = "pca",
) -> PCAModel:
    """PCA of M aligned shapes through the M x M Gram matrix, in the paper's convention.

    Parameters
    ----------
    shapes : (M, V, 3) float, mm; or a list of M (V, 3) arrays; or a mapping name -> (V, 3)
        The aligned shapes (e.g. neutral and viseme models), M >= 2, no NaN.
    names : sequence of M str, optional
        Shape names (default ``"0"``, ..., ``"M-1"``, or the mapping's keys).
    sigma : ``"sample"`` or ``"paper"``
        The sigma convention of the model's synthesis (:data:`SIGMA_CONVENTIONS`).
    source : str
        Label used in error messages (e.g. the subject id).

    Returns
    -------
    PCAModel
        Mean, K <= M - 1 unit-norm components sorted by decreasing eigenvalue, eigenvalues
        (``C = X'X'^T``, no 1/M), CR, CCR, the (M, K) coefficients of the inputs and sigma.

    Raises
    ------
    InputError
        On fewer than two shapes, shapes that are not (V, 3) or differ in vertex count, a NaN or
        infinite coordinate (naming the shape), or shapes that are all identical.
    """
    _check_convention(sigma, source)
    stack, names = _stack_shapes(shapes, names, source)
    m = stack.shape[0]
    mean = stack.mean(axis=0)
    centred = (stack - mean).reshape(m, -1)  # rows are S'_j: X'^T, (M, 3V)
    gram = centred @ centred.T  # D = X'^T X', (M, M); C = X' X'^T (3V x 3V) is never formed
    mu, vectors = np.linalg.eigh(gram)
    order = np.argsort(mu)[::-1]
    mu, vectors = mu[order], vectors[:, order]

    rms_coordinate = np.sqrt(np.mean(stack**2)) if stack.size else 0.0
    spread = np.sqrt(max(mu[0], 0.0) / centred.size)  # RMS of the centred data
    if not spread > SPREAD_RTOL * rms_coordinate or mu[0] <= 0:
        raise InputError(source, f"shapes: all {m} shapes are identical, PCA has no components")
    k = int(np.count_nonzero(mu > EIGEN_RTOL * mu[0]))
    k = min(k, m - 1)
    mu, vectors = mu[:k], vectors[:, :k]

    components = vectors.T @ centred  # e_i = X' ê_i, as rows (K, 3V)
    components /= np.linalg.norm(components, axis=1, keepdims=True)
    components = _fix_signs(components)
    coefficients = centred @ components.T  # (M, K): omega = e^T (S_j - mean)
    cr, ccr = contribution_rates(mu, source=source)
    return PCAModel(
        mean=mean,
        components=components.reshape(k, -1, 3),
        eigenvalues=mu,
        cr=cr,
        ccr=ccr,
        coefficients=coefficients,
        names=names,
        sigma=sigmas(mu, coefficients, sigma, source=source),
        sigma_convention=sigma,
    )


def project(model: PCAModel, shape, *, source: str = "pca") -> np.ndarray:
    """PCA coefficients of a shape: :math:`\\omega = (e_1 \\dots e_K)^T (S - \\bar S)`.

    Parameters
    ----------
    model : PCAModel
    shape : (V, 3) float, mm
        A shape aligned to the model's frame, with the model's vertex count, no NaN.
    source : str
        Label used in error messages.

    Returns
    -------
    (K,) float64, mm
        The coefficients (Table 2 style).
    """
    arr = np.asarray(shape, dtype=np.float64)
    if arr.shape != model.mean.shape:
        raise InputError(source, f"shape: expected {model.mean.shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise InputError(source, "shape: contains non-finite coordinates")
    k = model.n_components
    return model.components.reshape(k, -1) @ (arr - model.mean).ravel()


def synthesize(
    model: PCAModel, alpha, *, alpha_limit: float = ALPHA_LIMIT, source: str = "pca"
) -> np.ndarray:
    """A novel shape from the PCA model (Eq. 2).

    :math:`S = \\bar S + \\sum_i \\alpha_i \\sigma_i e_i`, sigma in the model's convention
    (``model.sigma``; the paper's is sqrt(lambda_i)).

    Parameters
    ----------
    model : PCAModel
    alpha : (K',) float, K' <= K
        Blending parameters of the first K' components, each in ``[-alpha_limit, alpha_limit]``.
    alpha_limit : float
        The bound of Eq. 2 (paper: 3).
    source : str
        Label used in error messages.

    Returns
    -------
    (V, 3) float64, mm
        The synthesised shape; ``alpha = 0`` gives the mean exactly.

    Raises
    ------
    InputError
        If alpha is not 1-D, has more entries than the model has components, or an entry is
        non-finite or outside the bound (the message names its index).
    """
    a = np.asarray(alpha, dtype=np.float64)
    if a.ndim != 1:
        raise InputError(source, f"alpha: expected a (K,) array, got shape {a.shape}")
    if a.size > model.n_components:
        raise InputError(
            source, f"alpha: {a.size} values but the model has {model.n_components} components"
        )
    bad = ~(np.abs(a) <= alpha_limit)  # also catches NaN
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(
            source,
            f"alpha[{i}] (component {i + 1}) = {a[i]}: expected within "
            f"[-{alpha_limit:g}, {alpha_limit:g}]",
        )
    scale = a * model.sigma[: a.size]
    return model.mean + np.tensordot(scale, model.components[: a.size], axes=1)


def pca_tables(model: PCAModel) -> tuple[list[dict], list[dict]]:
    """The paper's Table 1 and Table 2 as rows for a TSV writer.

    Returns
    -------
    eigen_rows : list of K dict
        ``{"component": i (1-based), "eigenvalue", "cr", "ccr", "sigma_{convention}_mm"}``
        (Table 1; the last column, sigma_i of Eq. 2, names its convention:
        ``sigma_sample_mm`` or ``sigma_paper_mm``).
    coefficient_rows : list of M dict
        ``{"take": name, "w1": ..., "wK": ...}`` (Table 2), in input order.
    """
    sigma = f"sigma_{model.sigma_convention}_mm"
    eigen_rows = [
        {
            "component": i + 1,
            "eigenvalue": float(lam),
            "cr": float(cr),
            "ccr": float(ccr),
            sigma: float(s),
        }
        for i, (lam, cr, ccr, s) in enumerate(
            zip(model.eigenvalues, model.cr, model.ccr, model.sigma, strict=True)
        )
    ]
    coefficient_rows = [
        {"take": name, **{f"w{i + 1}": float(w) for i, w in enumerate(row)}}
        for name, row in zip(model.names, model.coefficients, strict=True)
    ]
    return eigen_rows, coefficient_rows


__all__ = [
    "ALPHA_LIMIT",
    "DEFAULT_PCA_BLENDS",
    "EIGEN_RTOL",
    "PCAModel",
    "SIGMA_CONVENTIONS",
    "contribution_rates",
    "pca",
    "pca_tables",
    "project",
    "sigmas",
    "synthesize",
]
