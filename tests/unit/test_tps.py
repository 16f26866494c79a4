"""Thin-plate spline: exact interpolation, scipy oracle, affine precision, the paper's system."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RBFInterpolator

from scan2morph.errors import InputError
from scan2morph.template import TPS, build_template, noise_gain, subdivide_template, tps_warp
from scan2morph.template.mesh import FIDUCIAL_SETS, IBUG_CANONICAL


def _scattered(rng, m):
    return rng.uniform(-1.5, 1.5, (m, 2))


@pytest.mark.parametrize("m", [3, 4, 20, 28, 60])
def test_interpolates_exactly_and_matches_scipy(m):
    rng = np.random.default_rng(m)
    src = _scattered(rng, m)
    dst = 320 + 65 * src + rng.normal(0, 3.0, (m, 2))
    spline = TPS.fit(src, dst)
    assert np.abs(spline(src) - dst).max() < 1e-9
    pts = rng.uniform(-2.0, 2.0, (700, 2))
    ref = RBFInterpolator(src, dst, kernel="thin_plate_spline", degree=1)(pts)
    np.testing.assert_allclose(spline(pts), ref, rtol=0, atol=1e-6)


def test_solution_satisfies_the_papers_linear_system():
    rng = np.random.default_rng(5)
    src = IBUG_CANONICAL[np.array(FIDUCIAL_SETS["open"]) - 1]
    dst = 300 + 70 * src + rng.normal(0, 2.0, src.shape)
    spline = TPS.fit(src, dst)
    r = np.linalg.norm(src[:, None] - src[None], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(r > 0, r**2 * np.log(r), 0.0)
    p = np.column_stack([np.ones(len(src)), src])
    # v_j = A(u_j) + sum_i lambda_i phi(|u_j - u_i|) and the side conditions P^T lambda = 0
    np.testing.assert_allclose(phi @ spline.weights + p @ spline.affine, dst, atol=1e-9)
    np.testing.assert_allclose(p.T @ spline.weights, 0.0, atol=1e-9)


def test_three_points_give_the_affine_map_through_them():
    src = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    dst = np.array([[10.0, 20.0], [13.0, 21.0], [9.0, 25.0]])
    pts = np.random.default_rng(1).uniform(-3, 3, (50, 2))
    # affine map through the three pairs: dst0 + x (dst1 - dst0) + y (dst2 - dst0)
    expect = dst[0] + pts[:, :1] * (dst[1] - dst[0]) + pts[:, 1:] * (dst[2] - dst[0])
    np.testing.assert_allclose(TPS.fit(src, dst)(pts), expect, atol=1e-9)


def test_warp_does_not_depend_on_the_template_frames_scale_or_origin():
    # r^2 log(s r) = s^2 (r^2 log r) + s^2 log(s) r^2, and the r^2 part is affine under the side
    # conditions: the spline composed with a similarity of its source is the same map.
    rng = np.random.default_rng(2)
    src = _scattered(rng, 15)
    dst = 200 + 50 * src + rng.normal(0, 4.0, src.shape)
    pts = rng.uniform(-1.5, 1.5, (300, 2))
    s, t = 37.0, np.array([-4.0, 11.0])
    np.testing.assert_allclose(
        TPS.fit(s * src + t, dst)(s * pts + t), TPS.fit(src, dst)(pts), atol=1e-7
    )


def test_blocked_evaluation_and_function_form_agree():
    rng = np.random.default_rng(3)
    src = _scattered(rng, 10)
    dst = src**2 + src
    spline = TPS.fit(src, dst)
    pts = rng.uniform(-1.5, 1.5, (70_000, 2))  # more than one evaluation block
    ref = RBFInterpolator(src, dst, kernel="thin_plate_spline")(pts)
    np.testing.assert_allclose(spline(pts), ref, atol=1e-6)
    np.testing.assert_array_equal(tps_warp(src, dst, pts[:100]), spline(pts[:100]))


@pytest.mark.parametrize("n", [1, 4095, 4097, 70_000, 140_000])
def test_the_kernel_in_chunks_gives_the_one_pass_numbers(n):
    """A block's kernel values computed a chunk at a time (:data:`CHUNK`) are those of one
    pass over the block, and the product with the weights stays one per block: the warp is
    bit for bit the formula evaluated block by block."""
    from scan2morph.template.tps import BLOCK, _pairwise, _phi

    rng = np.random.default_rng(n)
    src = rng.uniform(-1.0, 1.0, (68, 2))
    spline = TPS.fit(src, rng.uniform(0.0, 600.0, (68, 2)))
    pts = rng.uniform(-1.2, 1.2, (n, 2))
    expected = np.concatenate(
        [
            spline.affine[0]
            + b @ spline.affine[1:]
            + _phi(_pairwise(b, spline.centres)) @ spline.weights
            for b in (pts[s : s + BLOCK] for s in range(0, n, BLOCK))
        ]
    )
    np.testing.assert_array_equal(spline(pts), expected)


@pytest.mark.parametrize(
    "src, dst, size, match",
    [
        (np.zeros((4, 3)), np.zeros((4, 3)), None, r"expected two \(m, 2\) arrays"),
        (np.eye(3, 2), np.zeros((4, 2)), None, r"expected two \(m, 2\) arrays"),
        (np.zeros((0, 2)), np.zeros((0, 2)), None, "at least 3 points, got 0"),
        (
            [[0, 0], [1, 0], [0, 1]],
            [[0, 0], [np.inf, 0], [0, 1]],
            None,
            "image point 1 is not finite",
        ),
        ([[0, 0], [1, 0], [0, 1], [1, 1e-12]], np.zeros((4, 2)), None, "points 1 and 3 coincide"),
        ([[0, 0], [2, 1], [4, 2]], [[0, 0], [1, 0], [0, 1]], None, "collinear"),
        ([[0, 0], [1, 0], [0, 1]], [[-0.6, 0], [1, 0], [0, 1]], (640, 480), "image point 0"),
        ([[0, 0], [1, 0], [0, 1]], [[5, 5], [1, 479.6], [0, 1]], (640, 480), "point 1 .* 640x480"),
    ],
)
def test_bad_input_raises(src, dst, size, match):
    with pytest.raises(InputError, match="^sub/take: fiducials: .*" + match):
        TPS.fit(np.asarray(src, float), np.asarray(dst, float), source="sub/take", image_size=size)


def test_points_on_the_image_border_are_accepted():
    # (-0.5, -0.5) is the top-left corner of the top-left pixel: still inside the image
    src = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    dst = np.array([[-0.5, -0.5], [639.5, 0.0], [0.0, 479.5]])
    assert np.abs(TPS.fit(src, dst, image_size=(640, 480))(src) - dst).max() < 1e-9


def test_noise_gain_matches_a_monte_carlo_of_noisy_fiducials():
    rng = np.random.default_rng(11)
    src = IBUG_CANONICAL[np.array(FIDUCIAL_SETS["open_corners"]) - 1]
    dst = 300 + 70 * src
    pts = np.vstack([src[:3], rng.uniform(-1.2, 1.2, (5, 2)) + [0, 1.0], [[1.6, 2.4], [0, 3.0]]])
    gain = noise_gain(src, pts)
    np.testing.assert_allclose(gain[:3], 1.0, atol=1e-9)  # interpolation: a fiducial's own noise
    sigma, n = 0.5, 4000
    warped = np.stack([TPS.fit(src, dst + rng.normal(0, sigma, dst.shape))(pts) for _ in range(n)])
    spread = warped.std(axis=0)  # (points, 2): both coordinates see the same gain
    # the sample std of n normal draws is within 3.5 / sqrt(2 n) of the truth (relative)
    expect = np.broadcast_to(sigma * gain[3:, None], spread[3:].shape)
    np.testing.assert_allclose(spread[3:], expect, rtol=3.5 / np.sqrt(2 * n))


def test_inner_lip_corners_raise_the_noise_gain_at_the_outline():
    template = build_template()
    fine = subdivide_template(template, 1)
    outline = fine.vertices[fine.boundary]
    mean_gain = {
        name: noise_gain(template.vertices[template.fiducial_set(name)[1]], outline).mean()
        for name in ("closed", "open", "open_corners")
    }
    # measured: closed 1.23, open 1.36, open_corners 1.86
    assert mean_gain["closed"] < mean_gain["open"] < 1.45 < 1.75 < mean_gain["open_corners"]


def test_noise_gain_bad_input():
    with pytest.raises(InputError, match="coincide"):
        noise_gain(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), np.zeros((1, 2)))


def test_pairwise_distances_are_scipys():
    """The spline's distances by coordinate: scipy's Euclidean distances to rounding, and bit
    for bit the broadcast formula they replace (so every warp is unchanged)."""
    from scipy.spatial.distance import cdist

    from scan2morph.template.tps import _pairwise

    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(300, 2)) * 50, rng.normal(size=(28, 2)) * 50
    got = _pairwise(a, b)
    np.testing.assert_allclose(got, cdist(a, b), rtol=1e-15, atol=0)
    np.testing.assert_array_equal(got, np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)))
