"""The face's canonical frame: a fixed grid in mm around the nose tip, and its feature channels.

A take's grid is resampled into a ``SIZE`` x ``SIZE`` grid of ``STEP_MM`` per cell, centred so
that the nose tip lands on :data:`NOSE_CELL`, using the scale the range data gives (px per mm
at the nose tip). Every detector stage works there, so one model serves every resolution and
camera. The channels (all computed in the canonical grid):

* ``depth``: depth behind the nose tip, mm / 30, clipped to [-0.5, 3] (no data: 3);
* ``nx``, ``ny``: the surface normal's image-plane components (camera frame; no data: 0);
* ``grey``: the luminance, band-passed (Gaussian 0.9 mm minus Gaussian 4.8 mm) and divided by
  its spread over the face: skin and lip edges, eyelids and brows, whatever the camera's gain.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from scan2morph.geometry import surface_normals
from scan2morph.landmarks.face import Face

#: mm per canonical cell.
STEP_MM = 0.6
#: Canonical grid side, cells (192 mm).
SIZE = 320
#: Canonical cell of the nose tip (x, y; x mid-grid, so a mirror image keeps it).
NOSE_CELL = np.array([159.5, 150.0])
#: Names of the channels, in order.
CHANNELS = ("depth", "nx", "ny", "grey")


@dataclass(frozen=True)
class Canonical:
    """A take resampled into the canonical frame.

    Attributes
    ----------
    channels : (SIZE, SIZE, 4) float32
        :data:`CHANNELS`.
    nose_px : (2,) float64
        The nose tip in the take's grid, px.
    px_per_cell : float
        Take pixels per canonical cell.
    """

    channels: np.ndarray
    nose_px: np.ndarray
    px_per_cell: float

    def to_image(self, cells: np.ndarray) -> np.ndarray:
        """Canonical coordinates (..., 2) cells -> the take's pixels (..., 2)."""
        return self.nose_px + self.px_per_cell * (np.asarray(cells) - NOSE_CELL)

    def to_cells(self, px: np.ndarray) -> np.ndarray:
        """The take's pixels (..., 2) -> canonical coordinates (..., 2) cells."""
        return NOSE_CELL + (np.asarray(px) - self.nose_px) / self.px_per_cell


def _warp(image: np.ndarray, nose_px: np.ndarray, k: float, border: float) -> np.ndarray:
    """Resample ``image`` into the canonical grid (bilinear; ``border`` outside)."""
    M = np.array([[k, 0.0, nose_px[0] - k * NOSE_CELL[0]], [0.0, k, nose_px[1] - k * NOSE_CELL[1]]])
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    return cv2.warpAffine(
        image, M, (SIZE, SIZE), flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=border
    )


def _normalised_blur(values: np.ndarray, ok: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of ``values`` (H, W, C) over the pixels ``ok`` (H, W) only."""
    w = cv2.GaussianBlur(ok.astype(np.float32), (0, 0), sigma)
    num = cv2.GaussianBlur(np.where(ok[..., None], values, 0.0).astype(np.float32), (0, 0), sigma)
    with np.errstate(invalid="ignore", divide="ignore"):
        return num / w[..., None]


def canonical(face: Face, color: np.ndarray) -> Canonical:
    """Resample a take into the canonical frame and compute its channels.

    Parameters
    ----------
    face : Face
        From :func:`scan2morph.landmarks.face.find_face` (the camera-frame points, the nose tip
        and the scale).
    color : (H, W, 3) uint8 or (H, W) uint8
        The take's colour (or grey) image on the same grid.

    Returns
    -------
    Canonical
    """
    k = STEP_MM * face.px_per_mm
    cam = _warp(face.cam.astype(np.float32), face.nose_px, k, np.nan)
    ok = np.isfinite(cam).all(axis=2)
    smooth = _normalised_blur(cam, ok, 1.2)
    smooth[~ok] = np.nan
    depth = (smooth[..., 2] - face.nose_cam[2]) / 30.0
    depth = np.clip(np.where(ok, depth, 3.0), -0.5, 3.0)
    normals = np.nan_to_num(surface_normals(smooth.astype(np.float64)), nan=0.0)
    grey = np.asarray(color, dtype=np.float32)
    if grey.ndim == 3:
        grey = grey @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    grey = _warp(np.ascontiguousarray(grey), face.nose_px, k, 0.0)
    band = cv2.GaussianBlur(grey, (0, 0), 1.5) - cv2.GaussianBlur(grey, (0, 0), 8.0)
    spread = float(np.std(band[ok])) if ok.sum() > 10 else 1.0
    band = np.clip(band / max(spread, 1e-3), -4.0, 4.0)
    channels = np.stack([depth, normals[..., 0], normals[..., 1], band], axis=-1)
    return Canonical(channels.astype(np.float32), face.nose_px.copy(), float(k))
