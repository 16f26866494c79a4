"""Point-to-mesh distances (scan2morph.io.mesh_distance) against independent oracles."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from scan2morph.io.mesh_distance import point_triangle_distance, surface_distance


def _sphere(n_lat: int = 24, n_lon: int = 48, r: float = 50.0):
    """A UV sphere of radius ``r`` mm: (vertices, faces)."""
    lat = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    lon = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    ring = np.stack(
        [
            np.outer(np.sin(lat), np.cos(lon)),
            np.outer(np.sin(lat), np.sin(lon)),
            np.outer(np.cos(lat), np.ones_like(lon)),
        ],
        axis=-1,
    ).reshape(-1, 3)
    v = np.vstack([[0, 0, 1], ring, [0, 0, -1]]) * r
    faces = []
    for j in range(n_lon):
        k = (j + 1) % n_lon
        faces.append([0, 1 + j, 1 + k])
        last = 1 + (n_lat - 2) * n_lon
        faces.append([len(v) - 1, last + k, last + j])
    for i in range(n_lat - 2):
        for j in range(n_lon):
            k = (j + 1) % n_lon
            a, b = 1 + i * n_lon + j, 1 + i * n_lon + k
            c, d = a + n_lon, b + n_lon
            faces += [[a, c, b], [b, c, d]]
    return v, np.array(faces)


@functools.cache
def _barycentric(samples: int) -> tuple[np.ndarray, np.ndarray]:
    """The (u, v) of a triangle's dense sampling: a grid of step 1/samples, u + v <= 1."""
    s = np.linspace(0, 1, samples + 1)
    u, v = np.meshgrid(s, s)
    keep = u + v <= 1
    return u[keep], v[keep]


def _brute(p, a, b, c, samples: int = 400):
    """Distance to a triangle by dense barycentric sampling (an upper bound within ~1/samples
    of its edge length of the true distance)."""
    u, v = _barycentric(samples)
    q = a + np.outer(u, b - a) + np.outer(v, c - a)
    q -= p
    return np.sqrt(np.einsum("ij,ij->i", q, q).min())


def test_point_triangle_regions_closed_form():
    a, b, c = np.array([0.0, 0, 0]), np.array([4.0, 0, 0]), np.array([0.0, 3, 0])
    cases = {  # point -> exact distance (face, edges, corners)
        (1.0, 1.0, 2.0): 2.0,  # above the face
        (2.0, -1.0, 0.0): 1.0,  # beyond edge ab
        (-2.0, 1.0, 0.0): 2.0,  # beyond edge ac
        (-1.0, -1.0, 0.0): np.sqrt(2.0),  # beyond corner a
        (5.0, 0.0, 3.0): np.sqrt(10.0),  # beyond corner b
        (4.0, 3.0, 0.0): 12.0 / 5.0,  # beyond edge bc (hypotenuse 3-4-5)
    }
    p = np.array(list(cases))
    n = len(p)
    got = point_triangle_distance(p, np.tile(a, (n, 1)), np.tile(b, (n, 1)), np.tile(c, (n, 1)))
    assert np.allclose(got, list(cases.values()), atol=1e-12)


def test_point_triangle_random_against_sampling():
    rng = np.random.default_rng(3)
    tri = rng.normal(size=(200, 3, 3)) * 10
    p = rng.normal(size=(200, 3)) * 15
    got = point_triangle_distance(p, tri[:, 0], tri[:, 1], tri[:, 2])
    ref = np.array([_brute(p[i], *tri[i]) for i in range(200)])
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    assert np.all(got <= ref + 1e-9)  # never beyond a point of the triangle
    assert np.all(ref - got <= edge / 400 * 1.5 + 1e-9)


def test_degenerate_triangles_are_segments_and_points():
    p = np.array([[1.0, 1.0, 0.0], [5.0, 0.0, 0.0]])
    a = np.zeros((2, 3))
    b = np.array([[2.0, 0, 0], [0.0, 0, 0]])
    c = np.array([[2.0, 0, 0], [0.0, 0, 0]])  # a segment, then a point
    assert np.allclose(point_triangle_distance(p, a, b, c), [1.0, 5.0])


@pytest.mark.parametrize("reach", [5.0, 0.1, 1000.0])
def test_surface_distance_sphere_against_brute_force(reach):
    v, f = _sphere()
    rng = np.random.default_rng(11)
    d = rng.normal(size=(30, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pts = d * rng.uniform(20, 90, size=(30, 1))  # inside and outside, near and far
    got = surface_distance(v, f, pts, reach)
    every = np.array(
        [point_triangle_distance(np.tile(p, (len(f), 1)), *(v[f[:, k]] for k in range(3))).min()
         for p in pts]
    )  # fmt: skip
    assert np.array_equal(got, every)  # the same triangle's distance, whatever the reach
    # and the faceted sphere is within its sag of the true one
    assert np.all(np.abs(got - np.abs(np.linalg.norm(pts, axis=1) - 50.0)) < 1.2)


def test_surface_distance_against_open3d():
    from scan2morph.open3d_light import open3d

    o3d = open3d()
    v, f = _sphere(16, 32, 40.0)
    pts = np.random.default_rng(5).uniform(-60, 60, size=(40, 3))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
    closest = scene.compute_closest_points(o3d.core.Tensor(pts.astype(np.float32)))["points"]
    ref = np.linalg.norm(closest.numpy() - pts, axis=1)
    assert np.allclose(surface_distance(v, f, pts, 5.0), ref, atol=1e-4)  # open3d: float32


def test_surface_distance_empty():
    assert np.isinf(
        surface_distance(np.zeros((3, 3)), np.zeros((0, 3)), np.ones((2, 3)), 1.0)
    ).all()
    assert surface_distance(np.eye(3), [[0, 1, 2]], np.zeros((0, 3)), 1.0).shape == (0,)
