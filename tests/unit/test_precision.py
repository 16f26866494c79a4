"""Tests of scan2morph.motion.precision: the click precision measured on stable landmarks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scan2morph.align.rigid import invert, transform_points
from scan2morph.errors import InputError
from scan2morph.motion.clicks import ClickedTake
from scan2morph.motion.precision import click_precision, resolve_click_noise
from scan2morph.template import build_template

W, H = 640, 480
#: A tilted plane (mm) as a function of the pixel coordinates: [x, y, 1] @ PLANE.
PLANE = np.array([[0.7, 0.0, 0.05], [0.0, 0.7, -0.03], [-224.0, -168.0, 1000.0]])
ALL = list(range(1, 69))


def _takes(n_takes, sigma, seed=0, misclick=None):
    """Takes of one plane in different poses; every take's pixel (u, v) sees the plane point
    of (u, v), clicked with Gaussian noise of ``sigma`` px around the iBUG points."""
    rng = np.random.default_rng(seed)
    truth = np.array([320.0, 230.0]) + 70.0 * build_template().ibug_xy
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    neutral_frame = np.stack([x, y, np.ones_like(x)], axis=-1) @ PLANE
    takes = {}
    for t in range(n_takes):
        to_neutral = np.eye(4)
        if t:
            to_neutral[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.05, 3)).as_matrix()
            to_neutral[:3, 3] = rng.normal(0, 10.0, 3)
        xyz = transform_points(invert(to_neutral), neutral_frame.reshape(-1, 3)).reshape(H, W, 3)
        clicks = truth + sigma * rng.standard_normal(truth.shape)
        if misclick is not None and t == misclick[0]:
            clicks[misclick[1] - 1] += misclick[2]
        takes[f"t{t}"] = ClickedTake(xyz, clicks, "closed", to_neutral)
    return takes


@pytest.mark.parametrize("sigma", [0.3, 1.0])
def test_recovers_the_click_noise_of_takes_in_different_poses(sigma):
    res = click_precision(_takes(8, sigma, seed=1), ALL, source="subj")
    assert res["click_noise_px"] == pytest.approx(sigma, rel=0.08)
    # of 544 Gaussian clicks a few may lie beyond 4 sigma and be taken for mis-clicks
    assert res["n_residuals"] + len(res["misclicks"]) == 8 * 68 and len(res["misclicks"]) <= 2
    # a residual is a click against the mean of the others: RMS sqrt(2 (1 + 1/7)) sigma
    r = np.concatenate(list(res["residual_px"].values()))
    assert np.sqrt(np.nanmean(r**2)) == pytest.approx(sigma * np.sqrt(2 * 8 / 7), rel=0.08)


def test_a_misclick_is_reported_and_left_out():
    takes = _takes(6, 0.5, seed=2, misclick=(3, 40, np.array([12.0, -9.0])))
    res = click_precision(takes, ALL, source="subj")
    assert [(t, n) for t, n, _ in res["misclicks"]] == [("t3", 40)]
    assert res["misclicks"][0][2] == pytest.approx(15.0, abs=2.0)
    assert res["click_noise_px"] == pytest.approx(0.5, rel=0.1)
    assert np.isnan(res["residual_px"]["t3"][39])


def test_clicks_without_range_data_are_not_used():
    takes = _takes(4, 0.5, seed=3)
    hole = takes["t1"].xyz.copy()
    u, v = np.round(takes["t1"].landmarks[27]).astype(int)
    hole[v - 3 : v + 4, u - 3 : u + 4] = np.nan  # no data under landmark 28
    takes["t1"] = ClickedTake(hole, takes["t1"].landmarks, "closed", takes["t1"].transform)
    res = click_precision(takes, ALL, source="subj")
    assert np.isnan(res["residual_px"]["t1"][27])
    assert res["n_residuals"] == 4 * 68 - 1


def test_too_few_clicks_give_no_estimate_and_say_why():
    res = click_precision(_takes(2, 0.5), [28, 40], source="subj")
    assert res["click_noise_px"] is None
    assert "4 stable-landmark clicks" in res["reason"] and "at least 6" in res["reason"]
    one = click_precision(dict(list(_takes(2, 0.5).items())[:1]), ALL, source="subj")
    assert one["click_noise_px"] is None and "nothing to compare" in one["reason"]


def test_resolve_uses_the_config_or_the_measurement_or_the_fallback():
    takes = _takes(6, 0.8, seed=4)
    auto = resolve_click_noise("auto", takes, ALL, 0.5, source="subj")
    assert auto["source"] == "measured"
    assert auto["click_noise_px"] == auto["measured_px"] == pytest.approx(0.8, rel=0.1)
    fixed = resolve_click_noise(0.3, takes, ALL, 0.5, source="subj")
    assert fixed["source"] == "config" and fixed["click_noise_px"] == 0.3
    assert fixed["measured_px"] == auto["measured_px"]  # measured all the same, as a check
    assert "configured 0.3 px (measured 0.8" in fixed["note"]
    two = dict(list(takes.items())[:2])
    few = resolve_click_noise("auto", two, [28, 40], 0.5, source="subj")
    assert few["source"] == "fallback" and few["click_noise_px"] == 0.5
    assert np.isnan(few["measured_px"]) and few["note"].startswith("assumed 0.5 px (not measurable")


@pytest.mark.parametrize(
    ("setting", "points", "match"),
    [
        ("measured", ALL, r"subj: motion_noise.click_noise_px: expected a number > 0 or 'auto'"),
        (0.0, ALL, r"click_noise_px: expected a number > 0 or 'auto', got 0.0"),
        (True, ALL, r"got True"),
        ("auto", [0, 28], r"subj/t0: stable points: expected iBUG numbers 1..68, got \[0, 28\]"),
        ("auto", [69], r"expected iBUG numbers 1..68"),
    ],
)
def test_bad_settings_are_named(setting, points, match):
    with pytest.raises(InputError, match=match):
        resolve_click_noise(setting, _takes(3, 0.5), points, 0.5, source="subj")
