"""Pieces of a take's mesh torn off the face: vertices sampled on another surface.

Skin stretches, but it does not tear. When a take's fit puts a patch of vertices a few pixels off
the skin at an occluding contour (onto the nose above the upper lip, into the mouth behind the
lips), the patch samples another surface: its vertices are valid samples, yet the mesh edges
that join the patch to the rest of the face are stretched many times their length in the
neutral. Cutting every edge stretched (or squeezed) beyond ``max_stretch`` splits the take's
mesh; a piece that is not the face's largest and lost an edge to the cut is torn off, and its
vertices are no measurement of where the skin went.

A vertex whose neighbours are all missing (in the take or the neutral) has no edge whose
stretch could be checked, so nothing tells a sample of the skin from one of another surface: it
counts as torn off too. At a mouth corner whose patch the scan left out, such a lone vertex
sampled the inside of the mouth 25 mm deep in one draw of the clicks, and the filling of the
patch round it took its motion (synth01 `too`: the click-noise error bar 0.105 -> 0.061 of the
motion without it). Two or more vertices joined by an edge are a piece whose own edges check
them against each other, and a hole may part a patch of skin from the rest; such a piece is
checked across the hole instead: each face vertex joined to it through one missing vertex
makes a chord, whose length changes from the neutral to the take as an edge's would, and a
piece whose chords' median ratio lies beyond ``max_stretch`` (or below its inverse) is torn
off. In one draw of synth01 `too`'s clicks, two vertices by the right mouth corner, in a patch
the scan left out, sampled 27-29 mm deep, and the filling took their motion: the click-noise
error bar of that seed's four draws was 0.110 of the motion, 0.037 with the chords. A piece beyond a gap of two
or more missing vertices has no chord, and is kept. Its known weakness: where the skin itself
stretches beyond ``max_stretch`` (by an opening mouth's corners), a real piece's chords stretch
with it and it is torn (and then filled from the face round it).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from scan2morph.errors import InputError
from scan2morph.geometry import edge_adjacency, unique_edges


def torn_off(
    take: np.ndarray,
    neutral: np.ndarray,
    faces: np.ndarray,
    max_stretch: float,
    source: str = "motion",
) -> np.ndarray:
    """The vertices of a take's mesh that tore off the face.

    Parameters
    ----------
    take, neutral : (V, 3) float, mm
        The take's vertices (in any rigid frame) and the neutral's; NaN rows are missing.
    faces : (F, 3) int
        Template triangles.
    max_stretch : float
        An edge longer than ``max_stretch`` times its length in the neutral, or shorter than
        its length divided by ``max_stretch``, is cut (> 1; ``inf`` cuts none).
    source : str
        ``subject/take`` label for error messages.

    Returns
    -------
    (V,) bool
        Finite take vertices in a piece of the cut mesh that is not its largest and that a cut
        edge joined to another piece, lone vertices outside the largest piece (every
        neighbour missing: no edge to check; a vertex no face uses is not one), and pieces of
        two or more vertices cut off only by missing vertices whose chords to the largest piece
        through one missing vertex have a median ratio beyond ``max_stretch`` (or below its
        inverse); those without such a chord are kept, as are the cut edges within a piece.
        The largest piece is taken to be the face: a take whose torn-off part is larger than
        the rest loses the rest instead (the motion stage logs how many vertices each take
        lost).
    """
    take = np.asarray(take, dtype=np.float64)
    neutral = np.asarray(neutral, dtype=np.float64)
    if take.shape != neutral.shape or take.ndim != 2 or take.shape[1] != 3:
        raise InputError(
            source, f"take: expected the neutral's (V, 3) shape {neutral.shape}, got {take.shape}"
        )
    if not max_stretch > 1.0:
        raise InputError(source, f"smoothing.max_stretch: expected a number > 1, got {max_stretch}")
    n = len(take)
    ok = np.isfinite(take).all(axis=1) & np.isfinite(neutral).all(axis=1)
    if not ok.any():
        return np.zeros(n, dtype=bool)
    edges = unique_edges(np.asarray(faces, dtype=np.int64).reshape(-1, 3))
    meshed = np.bincount(edges.ravel(), minlength=n) > 0
    e = edges[ok[edges[:, 0]] & ok[edges[:, 1]]]
    cut = ~_within(_stretch(take, neutral, e[:, 0], e[:, 1]), max_stretch)
    kept = e[~cut]
    graph = sp.coo_matrix((np.ones(len(kept)), (kept[:, 0], kept[:, 1])), shape=(n, n))
    _, label = csgraph.connected_components(graph, directed=False)
    largest = np.bincount(label[ok]).argmax()
    # a piece is torn when a cut edge joins it to another piece (not by a cut inside it), a
    # vertex when it has neighbours and none of them is there to check it against
    a, b = label[e[cut, 0]], label[e[cut, 1]]
    apart = a != b
    touched = np.zeros(label.max() + 1, dtype=bool)
    touched[a[apart]] = True
    touched[b[apart]] = True
    alone = meshed & (np.bincount(e.ravel(), minlength=n) == 0)
    torn = ok & (label != largest) & (touched[label] | alone)
    piece = ok & (label != largest) & ~torn
    return torn | _stretched_across_gaps(
        take, neutral, edges, ok, label == largest, piece, label, max_stretch
    )


def _stretch(take, neutral, i, j):
    """Length ratio, take over neutral, of the segments from vertices ``i`` to ``j`` (an edge of
    no length in the neutral keeps its ratio 1 while it stays so, infinite otherwise)."""
    before = np.linalg.norm(neutral[i] - neutral[j], axis=1)
    after = np.linalg.norm(take[i] - take[j], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(before > 0, after / before, np.where(after > 0, np.inf, 1.0))


def _within(ratio, max_stretch):
    """Whether length ratios are within ``max_stretch`` and its inverse."""
    return (ratio <= max_stretch) & (ratio >= 1.0 / max_stretch)


def _stretched_across_gaps(take, neutral, edges, ok, face, piece, label, max_stretch):
    """(V,) bool: the vertices of the pieces (``piece``: not the face, not torn) whose chords to
    the ``face`` are stretched. Each pair (p, q), p in a piece and q on the face, joined through
    one missing vertex is a chord whose length changes from the neutral to the take as an
    edge's would; a piece whose chords' median ratio lies beyond ``max_stretch`` (or below its
    inverse) sampled another surface. A piece with no such chord is kept."""
    adj = edge_adjacency(edges, len(ok))
    p, q = (adj @ sp.diags_array((~ok).astype(np.float64)) @ adj).nonzero()
    chord = piece[p] & face[q]
    p, q = p[chord], q[chord]
    out = np.zeros(len(ok), dtype=bool)
    ratio = _stretch(take, neutral, p, q)
    for lab in np.unique(label[p]):
        if not _within(np.median(ratio[label[p] == lab]), max_stretch):
            out |= piece & (label == lab)
    return out
