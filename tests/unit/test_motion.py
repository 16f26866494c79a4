"""Tests of scan2morph.motion: motion vectors, stencil mask (Dijkstra + spheres), smoothing."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from numpy.testing import assert_allclose, assert_array_equal
from scipy.sparse.csgraph import shortest_path

from scan2morph.errors import InputError
from scan2morph.motion import (
    Relief,
    dijkstra_path,
    fill_missing,
    laplacian_smooth,
    motion_vectors,
    stencil_mask,
)


def _grid_faces(nx: int, ny: int) -> np.ndarray:
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _grid(nx: int, ny: int, spacing: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.arange(nx) * spacing, np.arange(ny) * spacing)
    return np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny)], 1), _grid_faces(nx, ny)


def _torus_faces(n: int) -> np.ndarray:
    """Periodic n x n triangulated grid: every vertex has the same six neighbours
    (row, col) +- (0, 1), (1, 0), (1, 1)."""
    r, c = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")

    def idx(dr, dc):
        return (((r + dr) % n) * n + (c + dc) % n).ravel()

    a, b, cc, d = idx(0, 0), idx(0, 1), idx(1, 1), idx(1, 0)
    return np.concatenate([np.stack([a, b, cc], 1), np.stack([a, cc, d], 1)])


def _bumpy(nx: int, ny: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Jittered, curved grid: edge lengths all differ, so shortest paths are unique."""
    rng = np.random.default_rng(seed)
    v, f = _grid(nx, ny, spacing=3.0)
    v[:, :2] += rng.uniform(-0.8, 0.8, size=(len(v), 2))
    v[:, 2] = 10 * np.sin(v[:, 0] / 15) * np.cos(v[:, 1] / 20) + rng.normal(scale=0.3, size=len(v))
    return v, f


def _oracle_graph(v: np.ndarray, f: np.ndarray) -> sp.csr_array:
    """Independent edge graph: dense symmetric matrix of edge lengths from every half-edge."""
    n = len(v)
    w = np.zeros((n, n))
    for a, b in ((0, 1), (1, 2), (2, 0)):
        i, j = f[:, a], f[:, b]
        d = np.sqrt(((v[i] - v[j]) ** 2).sum(1))
        ok = np.isfinite(d)
        w[i[ok], j[ok]] = d[ok]
        w[j[ok], i[ok]] = d[ok]
    return sp.csr_array(w)


# ----------------------------------------------------------------------------- motion vectors


def test_motion_vectors_difference_and_nan_where_invalid():
    rng = np.random.default_rng(0)
    neutral = rng.normal(size=(8, 3))
    aligned = neutral + rng.normal(size=(8, 3))
    aligned[1] = np.nan
    valid_n = np.ones(8, dtype=bool)
    valid_n[5] = False
    d = motion_vectors(aligned, neutral, neutral_valid=valid_n)
    ok = np.ones(8, dtype=bool)
    ok[[1, 5]] = False
    assert_allclose(d[ok], aligned[ok] - neutral[ok], rtol=0, atol=0)
    assert np.isnan(d[~ok]).all()
    with pytest.raises(InputError, match=r"s01/car: aligned: expected the neutral's shape"):
        motion_vectors(aligned[:4], neutral, source="s01/car")
    with pytest.raises(InputError, match=r"s01/car: neutral_valid: expected \(8,\) bool"):
        motion_vectors(aligned, neutral, neutral_valid=np.ones(8), source="s01/car")


# ------------------------------------------------------------------------------------ Dijkstra


def test_dijkstra_path_matches_scipy_length_and_follows_edges():
    v, f = _bumpy(25, 20, seed=1)
    edges = {tuple(sorted(e)) for e in f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).tolist()}
    # Bellman-Ford on the symmetric graph as a directed one (scipy 1.17's BF with
    # directed=False reports a spurious negative cycle on this graph).
    dist = shortest_path(_oracle_graph(v, f), method="BF", directed=True, indices=[0, 137])
    for start, goal in [(0, 499), (0, 250), (137, 7), (137, 137)]:
        path = dijkstra_path(v, f, start, goal)
        assert path[0] == start and path[-1] == goal
        assert all(tuple(sorted(e)) in edges for e in zip(path[:-1], path[1:], strict=True))
        length = np.linalg.norm(np.diff(v[path], axis=0), axis=1).sum()
        assert length == pytest.approx(dist[0 if start == 0 else 1, goal], rel=1e-12)
        assert len(np.unique(path)) == len(path)


def test_dijkstra_path_goes_around_nan_vertices():
    v, f = _grid(12, 12)
    wall = np.arange(12) * 12 + 6  # column 6 ...
    v[wall[1:]] = np.nan  # ... blocked except at row 0
    path = dijkstra_path(v, f, 5 * 12 + 0, 5 * 12 + 11)
    assert np.isfinite(v[path]).all()
    assert 6 in path  # through the one gap
    dist = shortest_path(_oracle_graph(v, f), method="BF", directed=True, indices=[60])
    assert np.linalg.norm(np.diff(v[path], axis=0), axis=1).sum() == pytest.approx(dist[0, 71])


def test_dijkstra_path_bad_input():
    v, f = _grid(5, 5)
    two = np.r_[v, v + [100.0, 0, 0]]
    ff = np.r_[f, f + 25]
    with pytest.raises(
        InputError, match=r"s01: path_pairs\[0\] = \(0, 30\): .*different connected"
    ):
        dijkstra_path(two, ff, 0, 30, source="s01")
    with pytest.raises(InputError, match=r"s01: goal: vertex index 25 out of range \[0, 25\)"):
        dijkstra_path(v, f, 0, 25, source="s01")
    with pytest.raises(InputError, match=r"s01: start: vertex index -1 out of range"):
        dijkstra_path(v, f, -1, 3, source="s01")
    v_nan = v.copy()
    v_nan[3] = np.nan
    with pytest.raises(InputError, match=r"s01: goal: vertex 3 has no position"):
        dijkstra_path(v_nan, f, 0, 3, source="s01")
    with pytest.raises(InputError, match=r"s01: faces: vertex index out of range"):
        dijkstra_path(v, f + 1, 0, 3, source="s01")


# -------------------------------------------------------------------------------- stencil mask


def test_stencil_mask_equals_brute_force_spheres():
    v, f = _bumpy(30, 25, seed=2)
    v[[100, 101, 402]] = np.nan  # no position: never suppressed, paths avoid them
    pairs = np.array([[0, 29], [30, 700], [745, 20], [333, 360], [500, 510]])
    radius = 6.0
    suppressed, seeds = stencil_mask(v, f, pairs, radius_mm=radius, source="s01")
    expected_seeds = np.unique(np.concatenate([dijkstra_path(v, f, s, g) for s, g in pairs]))
    assert_array_equal(seeds, expected_seeds)
    d = np.sqrt(((v[:, None, :] - v[None, seeds, :]) ** 2).sum(-1)).min(axis=1)  # (V,) brute force
    assert_array_equal(suppressed, np.nan_to_num(d, nan=np.inf) <= radius)
    assert not suppressed[[100, 101, 402]].any()
    assert 0.1 < suppressed.mean() < 0.9


def test_stencil_mask_radius_is_inclusive():
    v, f = _grid(10, 3, spacing=2.0)
    suppressed, seeds = stencil_mask(v, f, np.array([[0, 0]]), radius_mm=4.0)
    assert_array_equal(seeds, [0])
    # Exactly 4 mm from the seed along the row is inside; sqrt(4^2+2^2) = 4.47 mm is not.
    assert_array_equal(np.flatnonzero(suppressed), [0, 1, 2, 10, 11, 20])


def test_stencil_mask_bad_input():
    v, f = _grid(5, 5)
    two = np.r_[v, v + [100.0, 0, 0]]
    ff = np.r_[f, f + 25]
    pairs = np.array([[0, 24], [1, 2], [3, 40]])
    with pytest.raises(
        InputError, match=r"s02: path_pairs\[2\] = \(3, 40\): .*different connected"
    ):
        stencil_mask(two, ff, pairs, source="s02")
    with pytest.raises(
        InputError, match=r"s02: path_pairs\[1\] goal: vertex index 99 out of range"
    ):
        stencil_mask(v, f, np.array([[0, 1], [2, 99]]), source="s02")
    with pytest.raises(InputError, match=r"s02: path_pairs: expected \(P, 2\)"):
        stencil_mask(v, f, np.array([0, 1]), source="s02")
    with pytest.raises(InputError, match=r"s02: path_pairs: expected integer"):
        stencil_mask(v, f, np.array([[0.0, 1.0]]), source="s02")
    with pytest.raises(InputError, match=r"s02: radius_mm: expected a positive number"):
        stencil_mask(v, f, np.array([[0, 1]]), radius_mm=0.0, source="s02")


# ------------------------------------------------------------------------------------ smoothing


def test_smoothing_keeps_a_constant_field():
    v, f = _bumpy(20, 15, seed=3)
    d = np.tile([1.5, -2.0, 0.25], (len(v), 1))
    assert_allclose(laplacian_smooth(d, f), d, rtol=0, atol=1e-13)


def test_smoothing_keeps_a_linear_field_in_the_grid_interior():
    n, iters = 40, 15
    v, f = _grid(n, n)
    a = np.array([[0.3, -1.2, 2.0], [0.7, 0.1, -0.4], [5.0, 1.0, -3.0]])
    d = np.c_[v[:, :2], np.ones(len(v))] @ a
    out = laplacian_smooth(d, f, w=0.5, iterations=iters)
    r, c = np.divmod(np.arange(n * n), n)
    # The boundary's change spreads one ring per step: rings >= iters from it are untouched.
    deep = np.minimum.reduce([r, c, n - 1 - r, n - 1 - c]) >= iters
    assert deep.sum() > 50
    assert_allclose(out[deep], d[deep], rtol=0, atol=1e-12)
    assert np.abs(out[~deep] - d[~deep]).max() > 1e-3  # the boundary did move


def _umbrella_eigenvalue(a, b):
    """Umbrella operator eigenvalue of the plane wave exp(i(a r + b c)) on the periodic grid."""
    return (2 * np.cos(a) + 2 * np.cos(b) + 2 * np.cos(a + b)) / 6 - 1


def test_smoothing_checkerboard_energy_drops_by_analytic_factor():
    n, w, iters = 24, 0.1, 30
    f = _torus_faces(n)
    r, c = np.divmod(np.arange(n * n), n)
    checker = (-1.0) ** (r + c)
    d = checker[:, None] * np.array([1.0, -2.0, 0.5])
    out = laplacian_smooth(d, f, w=w, iterations=iters)
    lam = _umbrella_eigenvalue(np.pi, np.pi)
    assert lam == pytest.approx(-4 / 3)
    factor = (1 + w * lam) ** iters  # (1 - 0.4/3)^30 = 0.013664
    assert_allclose(out, factor * d, rtol=1e-12, atol=1e-15)
    energy = (out**2).sum() / (d**2).sum()
    assert energy == pytest.approx(factor**2, rel=1e-10)
    assert energy == pytest.approx(1.8669e-4, rel=1e-3)


def test_smoothing_random_noise_matches_fft_spectral_oracle():
    n, w, iters = 24, 0.1, 30
    rng = np.random.default_rng(4)
    d = rng.normal(size=(n * n, 3))
    out = laplacian_smooth(d, faces=_torus_faces(n), w=w, iterations=iters)
    k = 2 * np.pi * np.fft.fftfreq(n)
    gain = (1 + w * _umbrella_eigenvalue(k[:, None], k[None, :])) ** iters
    expected = np.stack(
        [np.fft.ifft2(np.fft.fft2(d[:, j].reshape(n, n)) * gain).real.ravel() for j in range(3)], 1
    )
    assert_allclose(out, expected, atol=1e-12)
    assert (out**2).sum() < 0.2 * (d**2).sum()  # white noise energy drops


def test_smoothing_fixed_vertices_stay_exactly_zero():
    v, f = _bumpy(20, 20, seed=5)
    rng = np.random.default_rng(5)
    d = rng.normal(size=(len(v), 3)) + 3.0
    fixed = rng.random(len(v)) < 0.3
    out = laplacian_smooth(d, f, fixed=fixed)
    assert (out[fixed] == 0.0).all()
    assert np.abs(out[~fixed]).min() > 0
    # Zero is a Dirichlet boundary: the free vertices are pulled towards it.
    assert np.abs(out[~fixed]).mean() < np.abs(d[~fixed]).mean()


def test_missing_vertices_take_the_mean_of_their_neighbours():
    n = 12
    f = _torus_faces(n)
    rng = np.random.default_rng(6)
    d = rng.normal(size=(n * n, 3))
    missing = np.zeros(n * n, dtype=bool)
    missing[[14, 40, 77]] = True  # isolated: all their neighbours are known
    d_in = d.copy()
    d_in[missing] = np.nan
    filled = laplacian_smooth(d_in, f, iterations=0, missing=missing)
    r, c = divmod(14, n)
    nbrs = [((r + dr) % n) * n + (c + dc) % n for dr, dc in NEIGHBOURS]
    assert_allclose(filled[14], d[nbrs].mean(axis=0), rtol=1e-14)
    assert_allclose(filled[~missing], d[~missing], rtol=0, atol=0)
    assert_allclose(fill_missing(d_in, f), filled, rtol=0, atol=0)  # NaN rows count as missing


NEIGHBOURS = [(0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1)]


def test_missing_hole_is_filled_ring_by_ring():
    v, f = _grid(15, 15)
    d = np.tile([0.5, 1.0, -2.0], (len(v), 1))
    hole = np.linalg.norm(v[:, :2] - 7.0, axis=1) < 4.5  # several rings deep
    d_in = d.copy()
    d_in[hole] = 99.0  # garbage values under the missing flag are ignored
    out = laplacian_smooth(d_in, f, w=0.1, iterations=5, missing=hole)
    assert_allclose(out, d, atol=1e-13)
    # A missing vertex next to a fixed one takes zero from it into its mean.
    fixed = np.zeros(len(v), dtype=bool)
    fixed[0] = True
    missing = np.zeros(len(v), dtype=bool)
    missing[1] = True  # neighbours of 1: 0 (fixed), 2, 16, 17
    out = fill_missing(np.ones((len(v), 3)), f, missing=missing, fixed=fixed)
    assert_allclose(out[1], [0.75, 0.75, 0.75])
    assert (out[0] == 0).all()


def test_missing_component_without_known_vertices_becomes_zero():
    v, f = _grid(4, 4)
    ff = np.r_[f, f + 16]
    d = np.ones((32, 3))
    missing = np.r_[np.zeros(16, dtype=bool), np.ones(16, dtype=bool)]
    out = laplacian_smooth(d, ff, iterations=3, missing=missing)
    assert_allclose(out[:16], 1.0, atol=1e-14)
    assert (out[16:] == 0).all()


def test_confidence_shortens_each_vertex_step():
    """One step is d_i + w (1 - relief c_i) (mean of the neighbours - d_i), by hand on the torus;
    relief 0 is the paper's step whatever the confidence; a missing vertex counts as unmeasured."""
    n, w, relief = 10, 0.3, 0.8
    f = _torus_faces(n)
    rng = np.random.default_rng(11)
    d = rng.normal(size=(n * n, 3))
    c = rng.random(n * n)
    out = laplacian_smooth(d, f, w=w, iterations=1, relief=Relief(c, relief))
    for i in (0, 37, 99):
        r, col = divmod(i, n)
        nbrs = [((r + dr) % n) * n + (col + dc) % n for dr, dc in NEIGHBOURS]
        step = w * (1 - relief * c[i])
        assert_allclose(out[i], d[i] + step * (d[nbrs].mean(axis=0) - d[i]), rtol=1e-13)
    plain = laplacian_smooth(d, f, w=w, iterations=7)
    assert_allclose(laplacian_smooth(d, f, w=w, iterations=7, relief=Relief(c, 0.0)), plain)
    # full confidence with full relief: nothing moves
    ones = np.ones(n * n)
    assert_allclose(laplacian_smooth(d, f, iterations=30, relief=Relief(ones, 1.0)), d)
    # a missing vertex is filled, then smoothed with the full step however confident it was said
    missing = np.zeros(n * n, dtype=bool)
    missing[37] = True
    d_in = d.copy()
    d_in[37] = np.nan
    filled = laplacian_smooth(d_in, f, iterations=0, missing=missing)
    one = laplacian_smooth(d_in, f, w=w, iterations=1, missing=missing, relief=Relief(ones, 1))
    nbrs = [((3 + dr) % n) * n + (7 + dc) % n for dr, dc in NEIGHBOURS]
    assert_allclose(one[37], filled[37] + w * (filled[nbrs].mean(axis=0) - filled[37]))
    # NaN confidence counts as 0
    nan_c = np.where(np.arange(n * n) % 2 == 0, np.nan, 0.0)
    assert_allclose(
        laplacian_smooth(d, f, w=w, iterations=3, relief=Relief(nan_c, 1)),
        laplacian_smooth(d, f, w=w, iterations=3),
    )


def test_confidence_keeps_a_measured_step_and_smooths_the_noise():
    """A lip-like step in the motion (10 mm over one ring, measured: confidence 1) next to noisy
    unmeasured skin (confidence 0): against the true field, relief keeps the step that the
    paper's uniform step blurs, and removes the noise as much as the uniform step does."""
    n = 30
    v, f = _grid(n, n)
    x, y = v[:, 0], v[:, 1]
    truth = np.zeros((len(v), 3))
    truth[:, 1] = np.where(y >= n / 2, -10.0, 0.0)  # the lower half drops 10 mm
    measured = np.abs(y - (n - 1) / 2) < 4  # the step's rows, measured in the texture
    rng = np.random.default_rng(12)
    noisy = truth + np.where(measured[:, None], 0.0, rng.normal(0, 1.0, size=truth.shape))
    interior = (x > 2) & (x < n - 3) & (y > 2) & (y < n - 3)

    def rms(a, where):
        return float(np.sqrt(np.mean(np.sum((a[where] - truth[where]) ** 2, axis=1))))

    uniform = laplacian_smooth(noisy, f)
    relieved = laplacian_smooth(noisy, f, relief=Relief(measured.astype(float), 1.0))
    step = interior & measured
    assert rms(relieved, step) < 0.5 * rms(uniform, step)
    assert rms(uniform, step) > 1.0  # mm: the uniform step blurs the drop
    rest = interior & (np.abs(y - (n - 1) / 2) > 8)
    assert rms(relieved, rest) < 0.5 * rms(noisy, rest)
    assert rms(relieved, rest) == pytest.approx(rms(uniform, rest), rel=0.15)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"relief": Relief(None, 1.5)}, r"relief: expected 0 <= share <= 1"),
        ({"relief": Relief(None, -0.1)}, r"relief: expected 0 <= share <= 1"),
        ({"relief": Relief(np.ones(3), 1.0)}, r"confidence: expected \(16,\) values in \[0, 1\]"),
        (
            {"relief": Relief(np.full(16, 1.2), 1.0)},
            r"confidence: expected values in \[0, 1\], got 1.2",
        ),
        ({"w": 1.5}, r"w: expected 0 <= w <= 1"),
        ({"w": -0.1}, r"w: expected 0 <= w <= 1"),
        ({"iterations": -1}, r"iterations: expected an integer >= 0"),
        ({"iterations": 2.5}, r"iterations: expected an integer >= 0"),
        ({"fixed": np.ones(3, dtype=bool)}, r"fixed: expected \(16,\) bool"),
        ({"missing": np.ones(16)}, r"missing: expected \(16,\) bool"),
        ({"d": np.zeros((16, 2))}, r"d: expected \(V, 3\)"),
        ({"faces": np.array([[0, 1, 16]])}, r"faces: vertex index out of range"),
    ],
)
def test_smoothing_bad_input(kw, match):
    v, f = _grid(4, 4)
    args = {"d": np.zeros((16, 3)), "faces": f} | kw
    with pytest.raises(InputError, match=f"^s01/car: {match}"):
        laplacian_smooth(**args, source="s01/car")


def test_smoothing_does_not_modify_its_input():
    v, f = _grid(6, 6)
    d = np.random.default_rng(7).normal(size=(36, 3))
    d[3] = np.nan
    before = d.copy()
    laplacian_smooth(d, f, fixed=np.arange(36) < 5)
    assert_array_equal(d, before)
