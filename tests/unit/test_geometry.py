"""Tests of scan2morph.geometry: normals, edges and the harmonic fill against analytic answers
and independent oracles."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from scan2morph.errors import InputError
from scan2morph.geometry import (
    boundary_edges,
    face_normals,
    face_sides,
    harmonic_fill,
    unique_edges,
    vertex_normals,
)


def _grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """A flat (nx x ny) grid in z = 0, 2 mm spacing, counter-clockwise seen from +z."""
    x, y = np.meshgrid(2.0 * np.arange(nx), 2.0 * np.arange(ny))
    v = np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny)], axis=1)
    i = np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + nx, i.ravel() + nx + 1
    return v, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def _sphere(nt: int, nphi: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Latitude-longitude sphere (``nt`` rows of quads, ``nphi`` columns), every quad split in
    four about its centre so that each grid vertex's neighbourhood is mirror-symmetric; fans
    at the poles. Counter-clockwise seen from outside."""

    def pts(t, p):
        return radius * np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)

    th, ph = np.pi * np.arange(1, nt) / nt, 2 * np.pi * np.arange(nphi) / nphi
    grid = pts(*np.meshgrid(th, ph, indexing="ij")).reshape(-1, 3)
    tc = np.pi * (np.arange(nt - 2) + 1.5) / nt
    centre = pts(*np.meshgrid(tc, ph + np.pi / nphi, indexing="ij")).reshape(-1, 3)
    v = np.concatenate([grid, centre, [[0.0, 0.0, radius], [0.0, 0.0, -radius]]])
    north, south = len(v) - 2, len(v) - 1
    i, j = np.meshgrid(np.arange(nt - 2), np.arange(nphi), indexing="ij")
    a, b = i * nphi + j, i * nphi + (j + 1) % nphi
    c, d = a + nphi, b + nphi
    m = len(grid) + i * nphi + j
    quads = [np.stack(t, -1).reshape(-1, 3) for t in ((a, c, m), (c, d, m), (d, b, m), (b, a, m))]
    k = np.arange(nphi)
    last = (nt - 2) * nphi
    top = np.stack([np.full(nphi, north), k, (k + 1) % nphi], -1)
    bottom = np.stack([np.full(nphi, south), last + (k + 1) % nphi, last + k], -1)
    return v, np.concatenate([*quads, top, bottom])


def test_face_normals_length_is_twice_the_area():
    v = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 4.0, 0.0]])
    assert_allclose(face_normals(v, [[0, 1, 2]]), [[0.0, 0.0, 12.0]])
    assert_allclose(face_normals(v, [[0, 2, 1]]), [[0.0, 0.0, -12.0]])


def test_vertex_normals_of_a_flat_grid_point_up():
    v, f = _grid(7, 5)
    assert_allclose(vertex_normals(v, f), np.tile([0.0, 0.0, 1.0], (len(v), 1)), atol=1e-15)
    assert_allclose(vertex_normals(v, f[:, ::-1]), np.tile([0.0, 0.0, -1.0], (len(v), 1)))


def test_vertex_normals_of_a_sphere_are_radial():
    v, f = _sphere(60, 120, 80.0)
    assert np.all(np.sum(face_normals(v, f) * v[f].mean(axis=1), axis=1) > 0)  # outward
    n = vertex_normals(v, f)
    radial = v / np.linalg.norm(v, axis=1, keepdims=True)
    err = np.linalg.norm(n - radial, axis=1)
    polar = np.arccos(np.clip(radial[:, 2], -1.0, 1.0))
    assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    # Second order in the 3 deg spacing (times cot(polar) from the rows' unequal widths)
    mid = (polar > np.radians(30.0)) & (polar < np.radians(150.0))
    assert err[mid].max() < 1e-3
    assert err.max() < 5e-3  # the ring next to a pole, where cot(polar) is large
    assert err[[-2, -1]].max() < 1e-12  # the poles' fans are rotationally symmetric


def test_vertex_normals_nan_vertex_and_isolated_vertex_get_fill():
    v, f = _grid(4, 4)
    v = np.concatenate([v, [[50.0, 50.0, 50.0]]])  # vertex 16 belongs to no face
    v[6] = np.nan  # its faces are skipped; its neighbours keep the other faces
    n = vertex_normals(v, f)
    assert np.isnan(n[[6, 16]]).all()
    ok = np.ones(len(v), dtype=bool)
    ok[[6, 16]] = False
    assert_allclose(n[ok], np.tile([0.0, 0.0, 1.0], (ok.sum(), 1)), atol=1e-15)
    assert_array_equal(vertex_normals(v, f, fill=0.0)[[6, 16]], 0.0)


def test_vertex_normals_of_degenerate_faces_get_fill():
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    n = vertex_normals(v, [[0, 1, 2], [0, 1, 3]])
    assert_array_equal(n[2], [np.nan] * 3)  # only on a zero-area face
    assert_allclose(n[[0, 1, 3]], np.tile([0.0, 0.0, 1.0], (3, 1)))


def test_unique_edges_of_a_quad():
    # Two counter-clockwise triangles sharing the diagonal 0-2.
    edges = unique_edges(np.array([[0, 1, 2], [0, 2, 3]]))
    assert edges.dtype == np.int64
    assert_array_equal(edges, [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]])


def test_unique_edges_inverse_names_each_side():
    faces = np.array([[3, 1, 2], [2, 1, 0], [4, 4, 0]])  # the last face is degenerate
    edges, inverse = unique_edges(faces, return_inverse=True)
    assert_array_equal(edges, [[0, 1], [0, 2], [0, 4], [1, 2], [1, 3], [2, 3]])
    assert inverse.shape == (3, 3)
    assert inverse[2, 0] == -1
    for k, face in enumerate(faces):
        for s in range(3):
            if inverse[k, s] >= 0:
                a, b = face[s], face[(s + 1) % 3]
                assert_array_equal(edges[inverse[k, s]], [min(a, b), max(a, b)])


def test_boundary_edges_of_a_grid_and_of_a_closed_surface():
    """A (9 x 6) vertex grid's boundary is its 2 (8 + 5) = 26 outer edges, every one joining two
    vertices on the grid's rim; a closed tetrahedron has none."""
    _, f = _grid(9, 6)
    rim = (
        set(range(9))
        | set(range(45, 54))
        | {9 * r for r in range(6)}
        | {9 * r + 8 for r in range(6)}
    )
    edges = boundary_edges(f)
    assert edges.shape == (26, 2) and edges.dtype == np.int64
    assert all(a in rim and b in rim and a < b for a, b in edges.tolist())
    assert boundary_edges(np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]])).shape == (0, 2)


def test_unique_edges_match_an_independent_set_on_a_grid():
    _, f = _grid(9, 6)
    oracle = {
        tuple(sorted((int(f[k, s]), int(f[k, (s + 1) % 3]))))
        for k in range(len(f))
        for s in range(3)
    }
    assert [tuple(e) for e in unique_edges(f).tolist()] == sorted(oracle)
    assert len(oracle) == (8 * 6) + (9 * 5) + 8 * 5  # rows + columns + diagonals


def test_face_sides_run_round_each_face():
    faces = np.array([[3, 1, 2], [2, 1, 0]])
    assert_array_equal(face_sides(faces), [[3, 1], [1, 2], [2, 3], [2, 1], [1, 0], [0, 2]])
    assert face_sides(np.zeros((0, 3), dtype=np.int32)).shape == (0, 2)
    assert face_sides(faces.astype(np.int32)).dtype == np.int64


def test_unique_edges_of_no_faces():
    assert unique_edges(np.zeros((0, 3), dtype=np.int64)).shape == (0, 2)


def _grid_faces(nx: int, ny: int) -> np.ndarray:
    """Faces of an (nx x ny) vertex grid, each cell split along one diagonal (row-major)."""
    i = (np.arange(nx - 1)[None, :] + nx * np.arange(ny - 1)[:, None]).ravel()
    return np.concatenate([np.c_[i, i + 1, i + nx + 1], np.c_[i, i + nx + 1, i + nx]])


def test_harmonic_fill_reproduces_a_linear_field():
    """On a regular triangulated grid a linear function is harmonic under the uniform
    Laplacian: given on the boundary it is recovered inside (the oracle)."""
    nx, ny = 9, 7
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    faces = _grid_faces(nx, ny)
    values = np.c_[2.0 * x.ravel() - 3.0 * y.ravel() + 1.0, 0.5 * y.ravel()]
    known = ((x == 0) | (y == 0) | (x == nx - 1) | (y == ny - 1)).ravel()
    filled = harmonic_fill(np.where(known[:, None], values, 99.0), faces, known)
    assert_allclose(filled, values, atol=1e-9)
    assert_array_equal(filled[known], values[known])  # the known values are kept exactly


def test_harmonic_fill_solves_the_laplace_equation_of_a_dense_oracle():
    """On an irregular mesh the filled values satisfy the uniform Laplace equation: the oracle
    builds the graph Laplacian edge by edge from the faces and solves its unknown block densely
    (numpy), independently of the sparse code."""
    rng = np.random.default_rng(7)
    nx, ny = 8, 6
    faces = _grid_faces(nx, ny)
    n = nx * ny
    lap = np.zeros((n, n))
    for a, b, c in faces:
        for i, j in ((a, b), (b, c), (c, a)):
            lap[i, j] = lap[j, i] = -1.0
    np.fill_diagonal(lap, 0.0)
    np.fill_diagonal(lap, -lap.sum(axis=1))
    known = rng.random(n) < 0.35
    known[0] = True
    values = rng.normal(size=(n, 3))
    u, k = ~known, known
    oracle = values.copy()
    oracle[u] = np.linalg.solve(lap[np.ix_(u, u)], -lap[np.ix_(u, k)] @ values[k])
    filled = harmonic_fill(np.where(known[:, None], values, np.nan), faces, known)
    assert_allclose(filled, oracle, rtol=0, atol=1e-12)
    assert_allclose((lap @ filled)[u], 0.0, atol=1e-12)  # each unknown is its neighbours' mean
    # a ridge pulls the unknowns towards `unreachable`: (L_uu + r I) x_u = -L_uk x_k + r c
    r, c = 0.5, 2.0
    pulled = values.copy()
    a = lap[np.ix_(u, u)] + r * np.eye(int(u.sum()))
    pulled[u] = np.linalg.solve(a, -lap[np.ix_(u, k)] @ values[k] + r * c)
    got = harmonic_fill(values, faces, known, unreachable=c, ridge=r)
    assert_allclose(got, pulled, rtol=0, atol=1e-12)
    assert np.abs(got - filled).max() > 0.01  # the ridge is not ignored


def test_harmonic_fill_unreachable_vertices_get_the_given_value():
    """An unknown vertex in a component without a known vertex has no interpolant: NaN by
    default, or the value asked for; the component with known vertices is not affected."""
    nx, ny = 5, 4
    faces = _grid_faces(nx, ny)
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    values = np.c_[x.ravel() + 2.0 * y.ravel()]
    known = ((x == 0) | (y == 0) | (x == nx - 1) | (y == ny - 1)).ravel()
    alone = np.concatenate([faces, [[nx * ny, nx * ny + 1, nx * ny + 2]]])
    more = np.vstack([values, [[5.0], [6.0], [7.0]]])
    mask = np.r_[known, False, False, False]
    nan = harmonic_fill(more, alone, mask)
    zero = harmonic_fill(more, alone, mask, unreachable=0.0)
    assert_allclose(nan[: nx * ny], values, atol=1e-12)
    assert np.isnan(nan[nx * ny :]).all()
    assert_array_equal(zero[nx * ny :], 0.0)
    assert_array_equal(zero[: nx * ny], nan[: nx * ny])
    assert_array_equal(harmonic_fill(values, faces, np.ones(nx * ny, bool)), values)


def test_harmonic_fill_names_bad_input():
    faces = _grid_faces(4, 4)
    values, known = np.zeros((16, 2)), np.ones(16, bool)
    for change, match in (
        ({"values": np.zeros(16)}, "expected \\(V, d\\)"),
        ({"known": np.ones(15, bool)}, "expected \\(V, d\\)"),
        ({"faces": faces + 16}, "faces"),
        ({"values": np.full((16, 2), np.nan)}, "finite"),
        ({"ridge": -1.0}, "ridge >= 0"),
        ({"ridge": 1e-12}, "finite unreachable"),
    ):
        kw = {"faces": faces, "values": values, "known": known, "ridge": 0.0} | change
        with pytest.raises(InputError, match="s/lip: .*" + match):
            harmonic_fill(kw["values"], kw["faces"], kw["known"], ridge=kw["ridge"], source="s/lip")
