"""Which outline vertices the shell model clamps: the whole outline (the paper) or only where the
subject's takes show that the face does not move.

The modal-analysis paper fixes the face's whole outline. On a face template the outline runs
over the forehead and temples (still skin) but also down the cheeks and round the jaw and chin,
which move in visemes and smiles (the chin by centimetres when the jaw opens). A clamped vertex
has zero displacement in every mode, so whatever the takes move there no number of modes can
rebuild. :func:`still_outline` measures, per outline vertex, how far the subject's takes move it
(median over the takes of the displacement's length, then a running median along the loop so
that one noisy vertex does not flip its neighbours) and clamps the vertices below a threshold;
when fewer than a minimum share of the outline is still, the stillest ones are clamped so that
the model stays held. The policy ``every_still`` takes the longest displacement over the takes
instead of the median: a vertex any take moves stays unclamped.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scan2morph.errors import InputError

#: Boundary policies: clamp every outline vertex (the paper), the ones the median take leaves
#: still, the ones every take leaves still, or none (a free model).
POLICIES = ("all", "still", "every_still", "none")
#: How :func:`outline_motion` sums up the takes at a vertex, by policy (``median`` otherwise).
REDUCTIONS = {"every_still": "max"}


@dataclass(frozen=True)
class OutlineChoice:
    """The clamped part of the outline and the measurements it was chosen from.

    Attributes
    ----------
    fixed : (V,) bool
        Vertices clamped (a subset of the outline).
    outline : (V,) bool
        The whole outline (what the paper clamps).
    motion_mm : (V,) float
        Per outline vertex: median (policy ``every_still``: the largest) over the takes of the
        length of its displacement, smoothed by a running median along the loop, mm; NaN off
        the outline (and on the outline when no take gives it a value).
    policy : str
        One of :data:`POLICIES`.
    """

    fixed: NDArray[np.bool_]
    outline: NDArray[np.bool_]
    motion_mm: NDArray[np.float64]
    policy: str


def outline_motion(
    loop: ArrayLike,
    fields: Sequence[ArrayLike],
    n_vertices: int,
    window: int = 2,
    reduce: str = "median",
) -> NDArray[np.float64]:
    """How far the takes move each vertex of a closed outline loop.

    Parameters
    ----------
    loop : (B,) int
        The outline's vertex indices in loop order.
    fields : sequence of (V, 3) float, mm
        Displacement (or motion) fields of the subject's takes; NaN rows are ignored.
    n_vertices : int
        V.
    window : int
        Half-width (vertices along the loop) of the running median.
    reduce : {"median", "max"}
        How the takes' displacement lengths at a vertex are summed up.

    Returns
    -------
    (V,) float, mm
        The median (or largest) over the takes of the displacement length, then the median over
        the ``2 window + 1`` loop neighbours; NaN off the loop and where no take has a value.
    """
    if reduce not in ("median", "max"):
        raise InputError("outline", f"reduce: expected 'median' or 'max', got {reduce!r}")
    loop = np.asarray(loop, dtype=np.int64)
    out = np.full(int(n_vertices), np.nan)
    if not fields or loop.size == 0:
        return out
    lengths = []
    for i, f in enumerate(fields):
        f = np.asarray(f, dtype=np.float64)
        if f.shape != (n_vertices, 3):
            raise InputError(f"field {i}", f"expected shape ({n_vertices}, 3), got {f.shape}")
        lengths.append(np.linalg.norm(f[loop], axis=1))
    stack = np.stack(lengths)
    finite = np.isfinite(stack).any(axis=0)
    per_vertex = np.full(loop.size, np.nan)
    summary = np.nanmax if reduce == "max" else np.nanmedian
    per_vertex[finite] = summary(stack[:, finite], axis=0)
    w = max(int(window), 0)
    shifts = np.stack([np.roll(per_vertex, s) for s in range(-w, w + 1)])
    smooth = np.full(loop.size, np.nan)
    ok = np.isfinite(shifts).any(axis=0)
    smooth[ok] = np.nanmedian(shifts[:, ok], axis=0)
    out[loop] = smooth
    return out


def still_outline(
    loop: ArrayLike,
    fields: Sequence[ArrayLike],
    n_vertices: int,
    policy: str = "still",
    still_mm: float = 1.0,
    min_fixed_share: float = 0.25,
    window: int = 2,
    source: str = "modal",
) -> OutlineChoice:
    """The outline vertices to clamp.

    Parameters
    ----------
    loop : (B,) int
        The outline in loop order (the template's ``boundary``).
    fields : sequence of (V, 3) float, mm
        The subject's measured displacement fields (viseme motion, expression displacement).
    n_vertices : int
        V.
    policy : {"all", "still", "every_still", "none"}
        ``"all"``: the whole outline (the paper). ``"still"``: the outline vertices whose
        :func:`outline_motion` (the median over the takes) is below ``still_mm``; a vertex
        without any measurement counts as still. ``"every_still"``: the same with the largest
        displacement over the takes (still in every take). ``"none"``: no vertex (a free
        model).
    still_mm : float
        Motion below which an outline vertex is still, mm.
    min_fixed_share : float
        Share of the outline clamped at least (the stillest vertices when too few are below
        ``still_mm``), in (0, 1].
    window : int
        Half-width of the running median along the loop, vertices.
    source : str
        Label for error messages.

    Returns
    -------
    OutlineChoice
    """
    if policy not in POLICIES:
        raise InputError(source, f"modal.fixed_outline: expected one of {POLICIES}, got {policy!r}")
    if not (np.isfinite(still_mm) and still_mm >= 0):
        raise InputError(source, f"modal.still_mm: expected a number >= 0, got {still_mm}")
    if not 0 < min_fixed_share <= 1:
        raise InputError(
            source, f"modal.min_fixed_share: expected a number in (0, 1], got {min_fixed_share}"
        )
    loop = np.asarray(loop, dtype=np.int64)
    if loop.ndim != 1 or loop.size == 0 or loop.min() < 0 or loop.max() >= n_vertices:
        raise InputError(source, f"outline: expected vertex indices in [0, {n_vertices - 1}]")
    outline = np.zeros(n_vertices, dtype=bool)
    outline[loop] = True
    motion = outline_motion(loop, fields, n_vertices, window, REDUCTIONS.get(policy, "median"))
    if policy == "none":
        return OutlineChoice(np.zeros_like(outline), outline, motion, policy)
    if policy == "all" or not fields:
        return OutlineChoice(outline.copy(), outline, motion, policy)
    on_loop = motion[loop]
    still = ~(on_loop >= still_mm)  # NaN (no measurement) counts as still
    need = int(np.ceil(min_fixed_share * loop.size))
    if still.sum() < need:
        order = np.argsort(np.where(np.isfinite(on_loop), on_loop, -np.inf), kind="stable")
        still = np.zeros(loop.size, dtype=bool)
        still[order[:need]] = True
    fixed = np.zeros(n_vertices, dtype=bool)
    fixed[loop[still]] = True
    return OutlineChoice(fixed, outline, motion, policy)


def still_skin(
    fields: Sequence[ArrayLike], n_vertices: int, still_mm: float = 1.0, source: str = "modal"
) -> NDArray[np.bool_]:
    """The vertices every take leaves still: where the skin can be tied to the bone.

    The skin over the skull's still parts (forehead, nose, temples, the sides of the face) does
    not slide; where it does differs between faces and takes (a sad face raises the lower
    forehead, a smile the lower temples). A vertex is still when the longest of the takes'
    displacements there is below ``still_mm``: only which skin moves is taken from the takes,
    no shape of their motion.

    Parameters
    ----------
    fields : sequence of (V, 3) float, mm
        The subject's measured displacement fields (viseme motion, expression displacement);
        NaN rows are ignored.
    n_vertices : int
        V.
    still_mm : float
        Displacement below which a vertex is still in a take, mm.
    source : str
        Label for error messages.

    Returns
    -------
    (V,) bool
        Still in every take that measures it; False where no take gives a value, and
        everywhere when ``fields`` is empty.
    """
    if not (np.isfinite(still_mm) and still_mm >= 0):
        raise InputError(source, f"modal.still_mm: expected a number >= 0, got {still_mm}")
    longest = np.full(int(n_vertices), np.nan)
    for i, f in enumerate(fields):
        f = np.asarray(f, dtype=np.float64)
        if f.shape != (n_vertices, 3):
            raise InputError(source, f"field {i}: expected shape ({n_vertices}, 3), got {f.shape}")
        longest = np.fmax(longest, np.linalg.norm(f, axis=1))
    return longest < still_mm
