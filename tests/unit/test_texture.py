"""Skin detail fixed to the skin: rest positions by ray casting, and detail that moves with it."""

import numpy as np
import pytest

from scan2morph.synth.texture import detail_image, rest_positions, skin_detail, value_noise


def _plane(z_mm=500.0, half=60.0, n=31):
    """A square grid mesh facing the camera at depth z_mm (vertices, faces)."""
    t = np.linspace(-half, half, n)
    X, Y = np.meshgrid(t, t)
    v = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z_mm)])
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    f = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    return v, f


def test_rest_positions_match_the_analytic_ray_plane_hit():
    v, f = _plane()
    rest = v * 2.0 + 7.0  # any affine rest frame: barycentric interpolation keeps it exact
    rays = np.array([[0.0, 0.0, 1.0], [0.05, -0.02, 1.0], [1.0, 0.0, 1.0]])
    got = rest_positions(v, f, rest, rays)
    hit = rays[:2] * (500.0 / rays[:2, 2:3])
    np.testing.assert_allclose(got[:2], hit * 2.0 + 7.0, atol=1e-3)
    assert np.isnan(got[2]).all()  # misses the 120 mm plane


def test_detail_is_seeded_and_strength_zero_is_flat():
    p = np.random.default_rng(0).uniform(-50, 50, (2000, 3))
    a, b = skin_detail(p, 7), skin_detail(p, 7)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, skin_detail(p, 8))
    np.testing.assert_array_equal(skin_detail(p, 7, 0.0), 1.0)
    # a lightly freckled skin: mostly within +-15 %, a few dark spots, never black
    lum = a.mean(axis=1)
    assert 0.05 < np.std(lum) < 0.2 and lum.min() > 0.3 and np.median(lum) > 0.85


def test_value_noise_is_continuous_and_interpolates_the_lattice():
    p = np.array([[1.0, 2.0, 3.0]])
    assert abs(value_noise(p, 1.0, 3)[0] - value_noise(p + 1e-9, 1.0, 3)[0]) < 1e-6
    v = value_noise(np.random.default_rng(1).uniform(0, 100, (20000, 3)), 2.0, 3)
    assert 0.0 <= v.min() and v.max() <= 1.0 and abs(v.mean() - 0.5) < 0.01


@pytest.mark.parametrize("shift_mm", [2.5, 5.0])
def test_detail_moves_with_the_skin(shift_mm):
    """Translating the surface (rest positions unchanged) translates the detail image by the
    projected shift: the detail is material, not painted on space."""
    v, f = _plane(n=61)
    K = np.array([[800.0, 0.0, 64.0], [0.0, 800.0, 64.0], [0.0, 0.0, 1.0]])
    where = np.ones((128, 128), bool)
    a = detail_image(where, v, f, v, K, seed=5, strength=1.0, supersample=1)
    moved = v + np.array([shift_mm, 0.0, 0.0])
    b = detail_image(where, moved, f, v, K, seed=5, strength=1.0, supersample=1)
    px = shift_mm * 800.0 / 500.0  # shift in pixels (a whole number here)
    assert px == int(px)
    k = int(px)
    np.testing.assert_allclose(
        b[:, k + 20 : 108], a[:, 20 : 108 - k], atol=1e-5
    )  # float32 ray casting
    assert np.abs(b - a).max() > 0.05  # the image did change


def test_blocks_give_the_numbers_of_one_pass():
    """The skin detail and the value noise of more points than a block (the million sub-pixels
    of a supersampled image) are computed block by block: the same numbers, bit for bit, as one
    pass over all of them (each point's value is its own), freckles and blotches included."""
    from scan2morph.synth import texture

    rng = np.random.default_rng(3)
    n = 2 * texture._BLOCK + 77
    points = rng.uniform(-40.0, 40.0, size=(n, 3))
    detail = texture.skin_detail(points, 12345)
    assert detail.shape == (n, 3) and detail.min() < 0.8 < 1.0 < detail.max()  # spots, mottling
    np.testing.assert_array_equal(detail, texture._detail_block(points, 12345, 1.0))
    noise = texture.value_noise(points, 1.2, 7)
    parts = [texture.value_noise(points[i : i + 1000], 1.2, 7) for i in range(0, n, 1000)]
    np.testing.assert_array_equal(noise, np.concatenate(parts))
