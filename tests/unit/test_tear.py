"""Tests of scan2morph.motion.tear: pieces of a take's mesh torn off the face."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from scan2morph.errors import InputError
from scan2morph.motion import laplacian_smooth, motion_vectors
from scan2morph.motion.tear import torn_off


def _grid(n: int = 12, spacing: float = 3.0):
    """An n x n grid in the z = 0 plane, mm, and its triangles."""
    x, y = np.meshgrid(np.arange(n) * spacing, np.arange(n) * spacing)
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]), i


def _patch(idx: np.ndarray) -> np.ndarray:
    """A 3 x 3 patch inside the grid."""
    return idx[4:7, 5:8].ravel()


def test_a_patch_sampled_on_another_surface_is_torn_off():
    """A patch whose vertices sample a surface 20 mm nearer (the nose over the upper lip) tears
    the mesh round it; exactly its vertices are returned."""
    neutral, faces, idx = _grid()
    take = neutral + [1.0, -2.0, 0.5]  # the take moved as a whole: no edge changes length
    take[_patch(idx), 2] -= 20.0
    torn = torn_off(take, neutral, faces, 2.0)
    expected = np.zeros(len(neutral), dtype=bool)
    expected[_patch(idx)] = True
    assert_array_equal(torn, expected)


def test_skin_that_stretches_or_moves_rigidly_is_kept():
    """Rotation, a 1.8 x stretch of the lower half and a smooth bulge tear nothing."""
    neutral, faces, _ = _grid()
    c, s = np.cos(0.4), np.sin(0.4)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    take = neutral.copy()
    lower = take[:, 1] > 15.0
    take[lower, 1] = 15.0 + 1.8 * (take[lower, 1] - 15.0)
    take[:, 2] += 6.0 * np.exp(-((take[:, 0] - 15) ** 2 + (take[:, 1] - 15) ** 2) / 60.0)
    assert not torn_off(take @ rot.T, neutral, faces, 2.0).any()


def test_a_piece_cut_off_by_missing_vertices_is_checked_across_them():
    """A patch ringed by one row of missing vertices is checked by the chords that join it to
    the face through them: 20 mm off (another surface) it is torn off, exactly its vertices; on
    the face, moved with it and stretched 1.4 times, it is kept. Beyond a gap of two rows no
    chord checks it, and it is kept however far it moved."""
    neutral, faces, idx = _grid()
    take = neutral + [1.0, -2.0, 0.5]
    ring = idx[3:8, 4:9].ravel()
    take[ring] = np.nan
    patch = _patch(idx)
    expected = np.zeros(len(neutral), dtype=bool)
    expected[patch] = True
    take[patch] = neutral[patch] + [1.0, -2.0, -19.5]
    assert_array_equal(torn_off(take, neutral, faces, 2.0), expected)
    centre = neutral[idx[5, 6]]
    take[patch] = centre + 1.4 * (neutral[patch] - centre) + [1.0, -2.0, 0.5]
    assert not torn_off(take, neutral, faces, 2.0).any()
    # slid 7 mm along the face: its chords stretch 2.2 times on one side and shrink to 0.2 on
    # the other; their median keeps it (their largest or smallest ratio would tear it)
    take[patch] = neutral[patch] + [8.0, -2.0, 0.5]
    assert not torn_off(take, neutral, faces, 2.0).any()
    wide = idx[2:9, 3:10].ravel()
    take[wide] = np.nan
    take[idx[5, 5:8]] = neutral[idx[5, 5:8]] + [0.0, 0.0, -20.0]  # a row of 3, two rows in
    assert not torn_off(take, neutral, faces, 2.0).any()


def test_a_lone_vertex_ringed_by_missing_vertices_is_torn_off():
    """A vertex whose every neighbour is missing has no edge to check: it is torn off wherever it
    lies (on the face's own surface too), and its 25 mm of another surface no longer leaks into
    the filling round it. Two such vertices with their edge between them are a piece, checked
    across the missing vertices round them (see the test before): 21 mm off they are torn, on
    the face they stay; a face of lone vertices keeps its largest
    piece (one vertex), and a vertex that no face uses is no lone vertex."""
    neutral, faces, idx = _grid()
    take = neutral + [0.0, 0.0, 2.0]
    hole = idx[3:8, 4:9].ravel()
    take[hole] = np.nan
    lone = idx[5, 6]
    for depth in (0.0, -25.0):
        take[lone] = neutral[lone] + [0.0, 0.0, 2.0 + depth]
        expected = np.zeros(len(neutral), dtype=bool)
        expected[lone] = True
        assert_array_equal(torn_off(take, neutral, faces, 2.0), expected)
    raw = motion_vectors(take, neutral, faces=faces, max_stretch=2.0)
    assert np.isnan(raw[hole]).all() and np.isfinite(np.delete(raw, hole, 0)).all()
    filled = laplacian_smooth(raw, faces, iterations=5, missing=~np.isfinite(raw).all(axis=1))
    np.testing.assert_allclose(filled[hole], np.tile([0.0, 0.0, 2.0], (len(hole), 1)), atol=1e-12)
    pair = idx[5, 6:8]
    take[pair] = neutral[pair] + [0.0, 0.0, -21.0]
    expected = np.zeros(len(neutral), dtype=bool)
    expected[pair] = True
    assert_array_equal(torn_off(take, neutral, faces, 2.0), expected)
    take[pair] = neutral[pair] + [0.0, 0.0, 2.0]
    assert not torn_off(take, neutral, faces, 2.0).any()
    scattered = np.full_like(neutral, np.nan)
    scattered[[idx[0, 0], idx[5, 5], idx[9, 9]]] = neutral[[idx[0, 0], idx[5, 5], idx[9, 9]]]
    assert torn_off(scattered, neutral, faces, 2.0).sum() == 2
    # a vertex no face uses has no neighbours to miss: it is not lone
    extra = np.vstack([take, [[0.0, 0.0, -25.0]]]), np.vstack([neutral, [[0.0, 0.0, 0.0]]])
    assert not torn_off(*extra, faces, 2.0).any()


def test_cuts_inside_a_piece_and_edges_of_no_length_tear_nothing():
    """A piece ringed by missing vertices keeps an edge squeezed inside it (a cut that joins the
    piece to itself is no tear), and an edge of no length in the neutral that stays so is no
    stretch, whatever max_stretch is."""
    neutral, faces, idx = _grid()
    take = neutral.copy()
    take[idx[3:8, 4:9].ravel()] = np.nan
    take[_patch(idx)] = neutral[_patch(idx)]  # the piece inside the ring
    inner = idx[5, 6]
    take[inner] = (neutral[inner] + neutral[idx[5, 7]]) / 2  # its edge to the right: 3 -> 1.5 mm
    assert not torn_off(take, neutral, faces, 1.8).any()
    neutral[inner] = neutral[idx[5, 7]]  # now an edge of no length in the neutral, as in the take
    take[inner] = neutral[inner]
    assert not torn_off(take, neutral, faces, 1e9).any()
    assert not torn_off(neutral, neutral, np.zeros((0, 3), dtype=int), 2.0).any()


def test_the_threshold_decides_and_inf_cuts_nothing():
    neutral, faces, idx = _grid()
    take = neutral.copy()
    # the edges round the patch stretch 2.24 x (3 -> 6.7 mm), its diagonals 1.73 x
    take[_patch(idx), 2] -= 6.0
    assert torn_off(take, neutral, faces, 1.7).sum() == 9
    assert not torn_off(take, neutral, faces, 1.8).any()  # the diagonals hold it
    assert not torn_off(take, neutral, faces, np.inf).any()


def test_torn_vertices_are_missing_motion_filled_from_the_face():
    """motion_vectors with the faces drops the torn patch; the smoothing fills it from the
    face's own motion (a uniform 2 mm), not the 20 mm of the other surface."""
    neutral, faces, idx = _grid()
    take = neutral + [0.0, 0.0, 2.0]
    take[_patch(idx), 2] -= 20.0
    raw = motion_vectors(take, neutral, faces=faces, max_stretch=2.0)
    assert np.isnan(raw[_patch(idx)]).all() and np.isfinite(np.delete(raw, _patch(idx), 0)).all()
    assert_array_equal(motion_vectors(take, neutral)[_patch(idx), 2], -18.0)
    filled = laplacian_smooth(raw, faces, iterations=5, missing=~np.isfinite(raw).all(axis=1))
    np.testing.assert_allclose(filled, np.tile([0.0, 0.0, 2.0], (len(raw), 1)), atol=1e-12)


@pytest.mark.parametrize(
    "take, stretch, match",
    [
        (np.zeros((5, 3)), 2.0, "take: expected"),
        (None, 1.0, "smoothing.max_stretch: expected a number > 1"),
        (None, np.nan, "smoothing.max_stretch"),
    ],
)
def test_bad_input(take, stretch, match):
    neutral, faces, _ = _grid(4)
    with pytest.raises(InputError, match=match):
        torn_off(neutral if take is None else take, neutral, faces, stretch, "s01/car")
