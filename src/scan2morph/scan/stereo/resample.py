"""Resampling of the rectified disparity into points of the unrectified left image grid."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np

from scan2morph.io.calibration import StereoCalibration

#: Rectified positions of the left pixels per rig (intrinsics, distortion, rectification, image
#: size): a rig's pairs share them, and a job reconstructs one rig.
_GRIDS: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def _rectified_grid(
    calib: StereoCalibration, rect: Mapping[str, Any], size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Rectified positions ``(u, v)``, each (H W,) float64, of the left image's pixels, rows
    first (:func:`cv2.undistortPoints` with ``R=R1, P=P1``), kept for the last few rigs."""
    width, height = size
    parts = (calib.K1, calib.D1, rect["R1"], rect["P1"], np.array([width, height], np.float64))
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in parts]
    key = b"".join(f"{a.shape};".encode() + a.tobytes() for a in arrays)
    if key not in _GRIDS:
        ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
        pix = np.stack([xs.ravel(), ys.ravel()], axis=-1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-12)
        uv = cv2.undistortPoints(
            pix, calib.K1, calib.D1, R=rect["R1"], P=rect["P1"], criteria=criteria
        )
        if len(_GRIDS) >= 4:
            _GRIDS.pop(next(iter(_GRIDS)))
        u, v = uv[:, 0, 0].copy(), uv[:, 0, 1].copy()
        u.flags.writeable = v.flags.writeable = False
        _GRIDS[key] = (u, v)
    return _GRIDS[key]


def _resample_left(
    disparity: np.ndarray,
    rect: Mapping[str, Any],
    calib: StereoCalibration,
    size: tuple[int, int],
    max_step_px: float,
) -> np.ndarray:
    """Points (H, W, 3) of the left image grid (unrectified left frame, mm) from the disparity.

    Every left pixel maps to a rectified position ``(u, v)``; it gets a point when the
    rectified pixel nearest to ``(u, v)`` is valid, so the valid region keeps its extent (no
    half-pixel erosion at its borders). The disparity there is the bilinear interpolation of
    the four rectified neighbours; a neighbour that is invalid or differs from the nearest one
    by more than ``max_step_px`` (across a discontinuity) is completed from the plane of the
    other three (``d00 + d11 = d01 + d10``) when they are valid and close, else replaced by the
    nearest one. Bilinear interpolation of the disparity is exact on planes.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified left disparity, px; NaN where invalid.
    rect : mapping
        :func:`~scan2morph.scan.stereo.rectify._rectify`'s transforms.
    calib : StereoCalibration
    size : (W, H)
        Left image size, px.
    max_step_px : float
        Largest difference from the nearest neighbour of a neighbour interpolated as is, px.

    Returns
    -------
    (H, W, 3) float64
        NaN where there is no point.
    """
    width, height = size
    u, v = _rectified_grid(calib, rect, size)

    hr, wr = disparity.shape
    u0 = np.floor(u).astype(np.int64)
    v0 = np.floor(v).astype(np.int64)
    inside = (u0 >= 0) & (u0 < wr - 1) & (v0 >= 0) & (v0 < hr - 1)
    u0c, v0c = np.where(inside, u0, 0), np.where(inside, v0, 0)
    # corners 0 (v0, u0), 1 (v0, u0 + 1), 2 (v0 + 1, u0), 3 (v0 + 1, u0 + 1)
    corners = np.stack(
        [
            disparity[v0c, u0c],
            disparity[v0c, u0c + 1],
            disparity[v0c + 1, u0c],
            disparity[v0c + 1, u0c + 1],
        ]
    )
    fu, fv = u - u0, v - v0
    nearest = (fu >= 0.5).astype(np.int64) + 2 * (fv >= 0.5).astype(np.int64)
    d_near = np.take_along_axis(corners, nearest[None], axis=0)[0]
    usable = np.abs(corners - d_near) <= max_step_px  # False where NaN
    completed = corners.copy()
    for i, (j, k, opposite) in enumerate(((1, 2, 3), (0, 3, 2), (0, 3, 1), (1, 2, 0))):
        plane = usable[j] & usable[k] & usable[opposite]
        fill = np.where(plane, corners[j] + corners[k] - corners[opposite], d_near)
        completed[i] = np.where(usable[i], corners[i], fill)
    ok = inside & np.isfinite(d_near)
    d = (
        completed[0] * (1 - fu) * (1 - fv)
        + completed[1] * fu * (1 - fv)
        + completed[2] * (1 - fu) * fv
        + completed[3] * fu * fv
    )
    d = np.where(ok, d, 1.0)
    Q = rect["Q"]
    w_ = Q[3, 0] * u + Q[3, 1] * v + Q[3, 2] * d + Q[3, 3]
    ok &= w_ * np.sign(Q[2, 3]) > 0  # in front of the camera
    # (u, v, d) -> rectified XYZ, as cv2.reprojectImageTo3D does per pixel; then R1^T maps the
    # rectified frame back to the left camera frame (cv2 transforms: numpy's tall-skinny
    # matmul is slow with a busy BLAS)
    uvd = np.stack([u, v, d], axis=-1).reshape(-1, 1, 3)
    xyz = cv2.transform(cv2.perspectiveTransform(uvd, Q), rect["R1"].T).reshape(-1, 3)
    xyz[~ok] = np.nan
    return xyz.reshape(height, width, 3)
