"""The camera of a range image estimated from its pixel grid (scan2morph.scan.view), and the
estimates kept per job: a repeated image is not refitted, a changed one is."""

from __future__ import annotations

import numpy as np
import pytest

from scan2morph.scan import view as view_module
from scan2morph.scan.view import scanner_view


def _rotation(axis, deg):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(deg)
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


def _range_image(rotation, centre, h=60, w=80, f=120.0):
    """A bumpy surface ~500 mm in front of a pinhole camera (f px, principal point at the
    image centre), in a frame where the camera sits at ``centre`` with rows of ``rotation`` as
    its axes: every pixel's point lies on that pixel's ray."""
    v, u = np.mgrid[0:h, 0:w].astype(float)
    x, y = (u - (w - 1) / 2) / f, (v - (h - 1) / 2) / f
    depth = 500.0 + 20.0 * np.sin(3 * x) * np.cos(2 * y) + 30.0 * x**2
    cam = np.stack([x * depth, y * depth, depth], axis=-1)
    return cam @ rotation + centre  # camera frame -> the image's frame


def test_estimate_is_the_camera_and_is_kept_per_image(monkeypatch):
    rotation, centre = _rotation([1, 2, 0.5], 30.0), np.array([100.0, -50.0, 20.0])
    xyz = _range_image(rotation, centre)
    fits = []
    dlt = view_module._dlt
    monkeypatch.setattr(view_module, "_dlt", lambda X, uv: fits.append(1) or dlt(X, uv))
    monkeypatch.setattr(view_module, "_ESTIMATES", type(view_module._ESTIMATES)())

    first = scanner_view(xyz)
    assert first.estimated
    np.testing.assert_allclose(first.centre, centre, atol=1e-6)
    assert abs(first.axis @ rotation[2]) == pytest.approx(1.0, abs=1e-12)
    n_fit = len(fits)
    assert n_fit >= 1

    again = scanner_view(xyz.copy())  # the same data in another array: not refitted
    assert again is first and len(fits) == n_fit

    # the same array moved in place: a fresh estimate, the moved camera
    shift = np.array([0.0, 0.0, 250.0])
    xyz += shift
    moved = scanner_view(xyz)
    assert len(fits) > n_fit
    np.testing.assert_allclose(moved.centre, centre + shift, atol=1e-6)


def test_kept_estimates_are_bounded(monkeypatch):
    monkeypatch.setattr(view_module, "_ESTIMATES", type(view_module._ESTIMATES)())
    rotation = _rotation([0, 1, 0], 20.0)
    for k in range(view_module._ESTIMATES_KEPT + 5):
        scanner_view(_range_image(rotation, np.array([float(k), 0.0, 0.0])))
    assert len(view_module._ESTIMATES) == view_module._ESTIMATES_KEPT
