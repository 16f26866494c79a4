"""Stable landmarks carried from the neutral onto a take (scan2morph.align.carry), against the
generator's exact landmarks."""

from __future__ import annotations

import numpy as np
import pytest

from scan2morph.align.carry import carry_stable
from scan2morph.scan import DEFAULT_REPAIR, repair_range
from scan2morph.synth.cohort import make_take

STABLE = (28, 37, 40, 43, 46)
IDX = np.asarray(STABLE) - 1


@pytest.fixture(scope="module")
def takes():
    out = {}
    for take, kind, label in (("neutral", "neutral", "neutral"), ("car", "viseme", "car")):
        r = make_take("c1", label, kind, take, 11)
        xyz = repair_range(r["xyz"], dict(DEFAULT_REPAIR), source=take)[0]
        out[take] = (xyz, r["truth"]["landmarks2d"])
    return out


def test_noisy_stable_points_are_carried_onto_the_true_ones(takes):
    (xyz_n, true_n), (xyz_t, true_t) = takes["neutral"], takes["car"]
    rng = np.random.default_rng(0)
    noisy = true_t + rng.normal(0.0, 2.0, size=true_t.shape)
    got = carry_stable(xyz_t, noisy, xyz_n, true_n, STABLE, "c1/car")
    err_before = np.linalg.norm(noisy[IDX] - true_t[IDX], axis=1)
    err_after = np.linalg.norm(got.points[IDX] - true_t[IDX], axis=1)
    print(
        f"\nstable points off the truth: before {err_before.round(2)}, after {err_after.round(2)}"
    )
    assert got.carried.all()
    assert err_after.max() < 0.5 and np.median(err_after) < 0.3
    # the other points are left as they were
    others = np.setdiff1d(np.arange(68), IDX)
    np.testing.assert_array_equal(got.points[others], noisy[others])
    np.testing.assert_allclose(got.shift_px, err_before, atol=0.6)


def test_a_neutral_error_is_carried_as_it_is(takes):
    """The neutral's own error moves every take's stable points with it: they agree."""
    (xyz_n, true_n), (xyz_t, true_t) = takes["neutral"], takes["car"]
    off = true_n.copy()
    off[IDX] += np.array([1.5, -1.0])
    got = carry_stable(xyz_t, true_t, xyz_n, off, STABLE, "c1/car")
    shift = got.points[IDX] - true_t[IDX]
    assert np.abs(shift - shift.mean(axis=0)).max() < 0.5  # one rigid shift, ...
    assert 1.0 < np.linalg.norm(shift.mean(axis=0)) < 2.5  # ... about the neutral's


def test_too_few_stable_points_with_data_leaves_the_take_as_it_is(takes):
    (xyz_n, true_n), (xyz_t, true_t) = takes["neutral"], takes["car"]
    far = true_t.copy()
    far[IDX] = -50.0  # off the grid
    got = carry_stable(xyz_t, far, xyz_n, true_n, STABLE, "c1/car")
    assert not got.carried.any()
    np.testing.assert_array_equal(got.points, far)
