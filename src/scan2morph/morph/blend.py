"""Morphing by blend shapes (Yano-Harada, section 5.1, Eq. 1).

A novel face is a convex-like combination of the base model :math:`S_0` and the viseme models
:math:`S_i`,

.. math:: S = \\sum_i w_i S_i + \\Big(1 - \\sum_i w_i\\Big) S_0,

with non-negative weights whose sum is at most one (the remainder goes to the base model).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import check_vertex_array

#: Slack allowed on ``sum(weights) <= 1`` (the paper's Fig. 12 right blend sums to exactly 1).
WEIGHT_SUM_SLACK = 1e-9

#: The paper's blends, name -> weights: Fig. 11's gradual series (one viseme at w = 0.3, 0.6,
#: 0.9, the others zero) and Fig. 12's three mixtures (left, centre, right). Treat as read-only.
DEFAULT_BLENDS: dict[str, dict[str, float]] = {
    **{
        f"{viseme}_{round(100 * w):02d}": {viseme: w}
        for viseme in ("car", "eel", "too")
        for w in (0.3, 0.6, 0.9)
    },
    "man60_eel30": {"man": 0.6, "eel": 0.3},
    "too50_car20": {"too": 0.5, "car": 0.2},
    "too80_eel10_car10": {"too": 0.8, "eel": 0.1, "car": 0.1},
}


def _as_shape(value, source: str, field: str, n_vertices: int | None = None) -> np.ndarray:
    """Validate one (V, 3) finite shape and return it as float64."""
    return check_vertex_array(
        value, field, source, n_vertices, ref="the base", hint="; fill them before blending"
    )


def blend(
    base,
    shapes: Mapping[str, np.ndarray] | np.ndarray,
    weights: Mapping[str, float],
    *,
    names: Sequence[str] | None = None,
    source: str = "blend",
) -> np.ndarray:
    """Blend viseme shapes with the base shape (Eq. 1 of the paper).

    Parameters
    ----------
    base : (V, 3) float, mm
        The base (neutral) shape :math:`S_0`.
    shapes : mapping name -> (V, 3) float, mm; or (M, V, 3) float, mm
        The viseme shapes :math:`S_i`, in the same frame as ``base`` (aligned). A stacked
        (M, V, 3) array is named by ``names`` (default ``"0"``, ..., ``"M-1"``).
    weights : mapping name -> float
        Blend weight of each named viseme; visemes not named have weight 0. Weights must be
        finite, non-negative and sum to at most 1 (+1e-9); the base gets ``1 - sum(weights)``.
    names : sequence of str, optional
        Names of the M shapes when ``shapes`` is a stacked array.
    source : str
        Label used in error messages (e.g. ``"subject/blend"``).

    Returns
    -------
    (V, 3) float64, mm
        The blended shape. A single weight of exactly 1 returns that viseme exactly, and empty
        weights return the base exactly.

    Raises
    ------
    InputError
        On a weight that is negative or non-finite, weights summing to more than 1, an unknown
        viseme name, or a shape that is not (V, 3), has another vertex count than the base, or
        contains NaN.
    """
    base = _as_shape(base, source, "base")
    n_vertices = base.shape[0]
    if isinstance(shapes, Mapping):
        table = dict(shapes)
    else:
        stack = np.asarray(shapes, dtype=np.float64)
        if stack.ndim != 3:
            raise InputError(
                source,
                f"shapes: expected a mapping name -> (V, 3) or an (M, V, 3) array, "
                f"got shape {stack.shape}",
            )
        if names is None:
            names = [str(i) for i in range(stack.shape[0])]
        names = [str(n) for n in names]
        if len(names) != stack.shape[0]:
            raise InputError(
                source, f"names: expected {stack.shape[0]} names (one per shape), got {len(names)}"
            )
        table = dict(zip(names, stack, strict=True))

    unknown = [name for name in weights if name not in table]
    if unknown:
        raise InputError(
            source,
            f"weights: unknown viseme {unknown[0]!r}; known visemes are {sorted(table)}",
        )
    values = {}
    for name, w in weights.items():
        try:
            values[name] = float(w)
        except (TypeError, ValueError):
            values[name] = float("nan")
        if not np.isfinite(values[name]) or values[name] < 0:
            raise InputError(
                source, f"weights[{name!r}] = {w!r}: expected a finite non-negative number"
            )
    total = float(sum(values.values()))
    if total > 1.0 + WEIGHT_SUM_SLACK:
        raise InputError(
            source,
            f"weights: sum to {total:.12g} > 1 ({dict(weights)}); the base takes 1 - sum(w) "
            "and cannot be negative",
        )
    # Validate every shape (not only the weighted ones): a bad shape is a bad input either way.
    stacked = {
        name: _as_shape(s, source, f"shapes[{name!r}]", n_vertices) for name, s in table.items()
    }
    used = [name for name, w in values.items() if w != 0.0]
    if not used:
        return base.copy()
    w = np.array([values[name] for name in used])
    s = np.stack([stacked[name] for name in used])
    # The paper's form (not S_0 + sum w (S_i - S_0)) keeps w = 1 exact: 1 * S_i + 0 * S_0.
    return np.tensordot(w, s, axes=1) + (1.0 - w.sum()) * base


__all__ = ["DEFAULT_BLENDS", "WEIGHT_SUM_SLACK", "blend"]
