"""Accuracy of a reconstructed range image against the true surface, pixel by pixel.

The face region of a synthetic take is its skin pixels (the truth's segment) whose centres lie
inside the convex hull of the 68 true landmarks: the face from brows to chin and between the
jaw contours, without eyes, brows, hair and the open mouth.
"""

from __future__ import annotations

from os import PathLike

import numpy as np
from scipy.spatial import ConvexHull

from scan2morph.errors import InputError


def face_region(skin: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """Skin pixels whose centres lie inside (or on) the convex hull of the landmarks.

    Parameters
    ----------
    skin : (H, W) bool
        Pixels that see skin.
    landmarks : (n, 2) float
        Pixel coordinates ((0, 0) = centre of the top-left pixel), n >= 3, not collinear.

    Returns
    -------
    (H, W) bool
    """
    skin = np.asarray(skin, dtype=bool)
    pts = np.asarray(landmarks, dtype=np.float64)
    hull = ConvexHull(pts)
    h, w = skin.shape
    lo = np.clip(np.floor(pts.min(axis=0)).astype(int), 0, [w - 1, h - 1])
    hi = np.clip(np.ceil(pts.max(axis=0)).astype(int), 0, [w - 1, h - 1])
    ys, xs = np.mgrid[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1]
    # hull.equations: rows (a, b, c) with a x + b y + c <= 0 inside, (a, b) unit outward normal
    eq = hull.equations
    dist = xs[..., None] * eq[:, 0] + ys[..., None] * eq[:, 1] + eq[:, 2]
    inside = np.zeros_like(skin)
    inside[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1] = np.all(dist <= 1e-9, axis=-1)
    return skin & inside


def stereo_accuracy(
    xyz: np.ndarray,
    truth: np.ndarray,
    face_mask: np.ndarray,
    source: str | PathLike[str] = "accuracy",
) -> dict:
    """Depth error and coverage of a reconstructed range image over a face region.

    Parameters
    ----------
    xyz : (H, W, 3) float
        Reconstruction, mm, NaN = no data, in the frame of ``truth`` (for a stereo take the left
        camera's, whose origin is the camera centre).
    truth : (H, W, 3) float
        True surface point of every pixel, mm (NaN allowed outside ``face_mask``).
    face_mask : (H, W) bool
        The pixels evaluated, e.g. :func:`face_region`.
    source : str or path-like
        Named in errors.

    Returns
    -------
    dict
        ``coverage``: share of the face pixels with data; ``n_face_px``, ``n_measured_px``;
        over the face pixels with data, the error is the distance between the measured and the
        true point of the pixel (for :func:`~scan2morph.scan.reconstruct_stereo`, whose
        points lie on the pixels' rays, the depth error along the ray): ``depth_rms_mm``,
        ``depth_median_mm``, ``depth_p95_mm``, ``depth_max_mm``, and ``depth_bias_mm`` the mean
        of ``|xyz| - |truth|`` (positive: farther from the camera than the truth). The error
        statistics are None when no face pixel has data.

    Raises
    ------
    InputError
        Shapes that disagree, an empty face region, face pixels without a true point.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    face = np.asarray(face_mask, dtype=bool)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or truth.shape != xyz.shape:
        raise InputError(
            source, f"xyz, truth: expected two (H, W, 3) arrays, got {xyz.shape} and {truth.shape}"
        )
    if face.shape != xyz.shape[:2]:
        raise InputError(source, f"face_mask: expected shape {xyz.shape[:2]}, got {face.shape}")
    n_face = int(np.count_nonzero(face))
    if n_face == 0:
        raise InputError(source, "face_mask: no pixel selected")
    true_pts = truth[face]
    missing_truth = ~np.all(np.isfinite(true_pts), axis=1)
    if missing_truth.any():
        raise InputError(
            source,
            f"truth: {int(missing_truth.sum())} face pixels have no true point "
            "(the face mask must lie on the true surface)",
        )
    pts = xyz[face]
    measured = np.all(np.isfinite(pts), axis=1)
    n_measured = int(np.count_nonzero(measured))
    out: dict = {
        "coverage": n_measured / n_face,
        "n_face_px": n_face,
        "n_measured_px": n_measured,
    }
    keys = ("depth_rms_mm", "depth_median_mm", "depth_p95_mm", "depth_max_mm", "depth_bias_mm")
    if n_measured == 0:
        return out | dict.fromkeys(keys)
    p, t = pts[measured], true_pts[measured]
    err = np.linalg.norm(p - t, axis=1)
    bias = np.linalg.norm(p, axis=1) - np.linalg.norm(t, axis=1)
    return out | {
        "depth_rms_mm": float(np.sqrt(np.mean(err**2))),
        "depth_median_mm": float(np.median(err)),
        "depth_p95_mm": float(np.percentile(err, 95)),
        "depth_max_mm": float(err.max()),
        "depth_bias_mm": float(bias.mean()),
    }


__all__ = ["face_region", "stereo_accuracy"]
