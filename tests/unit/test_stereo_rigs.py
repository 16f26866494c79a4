"""Dense stereo reconstruction of rigs other than the default scene's: the depth range derived
from the pair at other working distances, and curved matching windows on small balls.

The scenes (``tests/support/stereo_scene.py``, :func:`render_rig_scene`): a speckle-textured
ball before a plane, seen by a rig at another working distance, baseline, focal length, toe-in
or distortion. Ground truth is the exact ray hit of every left pixel centre.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from scan2morph.scan.stereo import DEFAULT_STEREO, reconstruct_stereo
from tests.support.stereo_scene import render_rig_scene, surface_errors


@functools.cache
def _ball_scene(radius_mm: float):
    """A speckled ball of ``radius_mm`` with its front 650 mm before the default synthetic
    rig's cameras (1300 px focal length, 0.5 mm per px), on a 320 x 240 crop of their sensor
    (the ball spans at most 80 px)."""
    rig = {"distance_mm": 650.0, "focal_px": 1300.0, "ball_radius_mm": radius_mm}
    return render_rig_scene(rig | {"width": 320, "height": 240}, seed=3)


def _cap_bias(radius_mm: float, curvature: bool) -> float:
    """Median signed depth error (mm, + farther) over the central cap of :func:`_ball_scene`
    (within half the ball's image radius of its centre: as curved as a nose tip at 10 mm, a
    cheek at 25 mm)."""
    scene = _ball_scene(radius_mm)
    params = {"patch_curvature": curvature, "min_coverage": 0.0}  # the ball: 4% of the image
    xyz, _ = reconstruct_stereo(scene.left, scene.right, scene.calib, params)
    err = np.linalg.norm(xyz, axis=2) - np.linalg.norm(scene.xyz, axis=2)
    ball = scene.surface == 0
    ys, xs = np.nonzero(ball)
    yy, xx = np.mgrid[: ball.shape[0], : ball.shape[1]]
    cap = np.hypot(yy - ys.mean(), xx - xs.mean()) < 0.5 * np.sqrt(ball.sum() / np.pi)
    cap &= np.isfinite(err)
    assert cap.sum() > 250
    return float(np.median(err[cap]))


def test_curved_windows_do_not_flatten_a_tip():
    """A window that assumes a plane flattens a convex tip by about sigma^2/2 times the
    Laplacian of its depth; the window that follows the disparity's curvature does not.

    Oracle: the ray-cast truth of two balls, radius 10 and 25 mm. The plane window's
    flattening at the cap is 0.056 and 0.022 mm in theory (1.5 px window, 0.5 mm per px).
    What both balls share (from the rendering) cancels in the difference between them. Measured: curved windows
    +0.018 / +0.011 mm (difference 0.007); the plane window on the 10 mm ball +0.065 mm, so
    there the curvature moves the cap by 0.047 mm (theory 0.056).
    """
    assert DEFAULT_STEREO["patch_curvature"] is True
    curved = {r: _cap_bias(r, True) for r in (10.0, 25.0)}
    assert abs(curved[10.0] - curved[25.0]) < 0.015
    assert all(abs(b) < 0.06 for b in curved.values())
    assert 0.03 < _cap_bias(10.0, False) - curved[10.0] < 0.08


# --- the depth range derived from the pair (the default) ------------------------------------

#: Rigs at other working distances (a face-sized ball, r = 100 mm, 'distance_mm' away, before a
#: plane at 1.8 'distance_mm'): near with a short baseline, far with a long one, toed-in with
#: strong distortion before a textured plane. On a 320 x 240 sensor (the range is derived from
#: the pair in px of disparity, and the ball fills the same share of the image as at 640 x 480
#: with twice these focal lengths).
RIGS = {
    "near 0.4 m, 60 mm": {"distance_mm": 400.0, "baseline_mm": 60.0, "focal_px": 250.0},
    "far 2 m, 300 mm": {
        "distance_mm": 2000.0,
        "baseline_mm": 300.0,
        "focal_px": 1000.0,
        "toe_in_deg": 4.3,
    },
    "toe-in 8 deg, k1 -0.15": {
        "toe_in_deg": 8.0,
        "k1": -0.15,
        "background": "textured",
        "focal_px": 450.0,
    },
}
SENSOR = {"width": 320, "height": 240}


@pytest.fixture(scope="module", params=list(RIGS))
def rig_result(request):
    scene = render_rig_scene(RIGS[request.param] | SENSOR, seed=5)
    xyz, report = reconstruct_stereo(scene.left, scene.right, scene.calib, source=request.param)
    return request.param, scene, xyz, report


def test_derived_depth_range_across_rigs(rig_result):
    """Default parameters: the coarse pass finds the ball (and a textured plane behind it) at
    any working distance; the fine pass measures the ball as with a hand-set range.

    Measured (near / far / toe-in, 320 x 240): ball coverage 0.91 / 0.88 / 0.81 (at 640 x 480
    0.90 / 0.90 / 0.86: the grazing rim the matching leaves is about as many px wide, so a
    larger share of a smaller ball), depth RMS 0.07 / 0.08 / 0.06 px of disparity (0.85 / 1.15
    / 0.63 mm, the whole ball to its grazing rim; 0.06 / 0.07 / 0.06 px at 640 x 480); derived
    ranges 291-582, 1850-2229 and 630-1551 mm (ball 401-482, 2006-2101 and 751-843 mm, the
    textured plane up to 1436 mm): the surfaces and the 100 mm margin on both sides.
    """
    name, scene, xyz, report = rig_result
    assert report["depth_range_source"] == "derived" and report["coarse_scale"] >= 1
    near, far = report["depth_range_mm"]
    ball, plane = scene.surface == 0, scene.surface == 1
    z_ball = scene.xyz[ball][:, 2]
    # the range holds the ball, and (textured) the plane, but is not much wider
    assert near < z_ball.min() and z_ball.max() < far
    assert z_ball.min() - near < 200.0
    if RIGS[name].get("background") == "textured":
        assert scene.xyz[plane][:, 2].max() < far < scene.xyz[plane][:, 2].max() + 200.0
    else:
        assert far - z_ball.max() < 200.0
    err, coverage = surface_errors(xyz, scene.xyz, ball)
    f_b = scene.calib.K1[0, 0] * scene.calib.baseline_mm
    mm_per_px = np.median(z_ball) ** 2 / f_b  # depth of one px of disparity at the ball
    assert coverage > 0.78
    assert np.sqrt(np.mean(err**2)) < 0.12 * mm_per_px
    assert report["timings_s"]["depth_range"] < 0.5 * report["timings_s"]["total"]
    if name.startswith("near"):  # deterministic (one rig suffices)
        again, report2 = reconstruct_stereo(scene.left, scene.right, scene.calib)
        np.testing.assert_array_equal(again, xyz)
        assert report2["depth_range_mm"] == report["depth_range_mm"]
