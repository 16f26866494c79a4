"""The pinhole camera of a take's pixel grid, estimated from the grid itself.

Every valid pixel of a range grid holds the surface point seen through that pixel, so the grid
fixes its camera: :func:`scan2morph.scan.view.scanner_view` gives the camera's centre and axes,
and a linear fit of ``column = fx X / Z + cx`` and ``row = fy Y / Z + cy`` in that frame gives
the focal lengths and principal point. Any right-handed frame of the scanner's XYZ works.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.scan.view import scanner_view

#: Valid pixels used for the fit (a fixed subsample of the grid).
_FIT_PIXELS = 4000


@dataclass(frozen=True)
class GridCamera:
    """The camera of a pixel grid.

    Attributes
    ----------
    centre : (3,) float64
        Camera centre in the grid's XYZ frame, mm.
    rotation : (3, 3) float64
        Rows: the camera's x, y, z axes in the XYZ frame (z towards the scene).
    focal : (2,) float64
        fx, fy, px (signed: a flipped axis gives a negative focal length).
    principal : (2,) float64
        cx, cy, px.
    """

    centre: np.ndarray
    rotation: np.ndarray
    focal: np.ndarray
    principal: np.ndarray

    def to_camera(self, xyz: np.ndarray) -> np.ndarray:
        """Points (..., 3) mm in the grid's frame -> the camera frame (Z = depth), mm."""
        return (np.asarray(xyz, dtype=np.float64) - self.centre) @ self.rotation.T

    def project(self, cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) mm -> pixel coordinates (..., 2), px."""
        cam = np.asarray(cam, dtype=np.float64)
        return cam[..., :2] / cam[..., 2:3] * self.focal + self.principal

    def px_per_mm(self, depth_mm: float) -> float:
        """Pixels per mm across the view at a depth of ``depth_mm``."""
        return float(np.sqrt(abs(self.focal[0] * self.focal[1]))) / float(depth_mm)


def grid_camera(xyz: np.ndarray) -> GridCamera | None:
    """Estimate the camera of a range grid.

    Parameters
    ----------
    xyz : (H, W, 3) float
        mm, NaN where there is no surface.

    Returns
    -------
    GridCamera or None
        None when fewer than 50 pixels have data or no camera explains them.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    h, w = xyz.shape[:2]
    ok = np.flatnonzero(np.isfinite(xyz).all(axis=2).reshape(-1))
    if len(ok) < 50:
        return None
    # the camera's centre and axes do not depend on the pixel pitch: every other pixel will do
    view = scanner_view(xyz[::2, ::2] if min(h, w) >= 200 else xyz)
    rotation = np.array(view.rotation, dtype=np.float64)
    idx = ok[:: max(1, len(ok) // _FIT_PIXELS)]
    cam = (xyz.reshape(-1, 3)[idx] - view.centre) @ rotation.T
    if np.median(cam[:, 2]) < 0:  # the axis' sign is free: look towards the data
        rotation = np.diag([1.0, -1.0, -1.0]) @ rotation
        cam = cam * np.array([1.0, -1.0, -1.0])
    if np.any(cam[:, 2] <= 0):
        return None
    focal, principal = np.zeros(2), np.zeros(2)
    pix = np.column_stack([idx % w, idx // w]).astype(np.float64)
    for k in range(2):
        ratio = cam[:, k] / cam[:, 2]
        A = np.column_stack([ratio, np.ones_like(ratio)])
        sol, *_ = np.linalg.lstsq(A, pix[:, k], rcond=None)
        focal[k], principal[k] = sol
    if np.any(np.abs(focal) < 1e-6) or not np.all(np.isfinite(focal)):
        return None
    return GridCamera(np.array(view.centre, dtype=np.float64), rotation, focal, principal)
