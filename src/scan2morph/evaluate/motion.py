"""Accuracy of viseme motion vectors and of the stencil mask against ground truth.

The true motion of a template vertex is the motion of the material point it sits on in the
neutral scan: its closest point on the true neutral surface (face + barycentric weights), carried
to the same barycentric point of the take's true mesh (all takes share one topology), expressed
in the neutral scanner frame.
"""

from __future__ import annotations

import numpy as np

from scan2morph.evaluate.truth import Truth, closest_points


def true_motion(neutral_vertices: np.ndarray, neutral: Truth, take: Truth) -> np.ndarray:
    """(V, 3) true motion (mm, neutral scanner frame) of each template vertex; NaN where invalid."""
    out = np.full(neutral_vertices.shape, np.nan)
    ok = np.isfinite(neutral_vertices).all(axis=1)
    skin = neutral.faces[neutral.skin_faces]
    face, bary, _ = closest_points(neutral.posed_vertices(), skin, neutral_vertices[ok])
    tri = skin[face]
    delta = np.einsum("qk,qkd->qd", bary, take.vertices[tri] - neutral.vertices[tri])
    out[ok] = delta @ neutral.pose[:3, :3].T
    return out


def motion_accuracy(
    motion: np.ndarray, motion_raw: np.ndarray, truth_motion: np.ndarray, suppressed: np.ndarray
) -> dict:
    """Errors of processed and raw motion over unmasked vertices, relative to the true motion RMS.

    Returns
    -------
    dict
        ``true_rms_mm``, ``rms_error_mm`` and ``relative_error`` (processed motion),
        ``raw_relative_error``, and ``masked_true_motion_share``: the share of the true motion's
        energy (sum of squared lengths) on vertices the mask suppresses.
    """
    ok = np.isfinite(truth_motion).all(axis=1)
    free = ok & ~suppressed
    true_rms = float(np.sqrt(np.mean(np.sum(truth_motion[free] ** 2, axis=1))))
    err = np.sqrt(np.mean(np.sum((motion[free] - truth_motion[free]) ** 2, axis=1)))
    raw_ok = free & np.isfinite(motion_raw).all(axis=1)
    raw_err = np.sqrt(np.mean(np.sum((motion_raw[raw_ok] - truth_motion[raw_ok]) ** 2, axis=1)))
    energy = np.sum(truth_motion[ok] ** 2, axis=1)
    return {
        "true_rms_mm": true_rms,
        "rms_error_mm": float(err),
        "relative_error": float(err / true_rms) if true_rms > 0 else float("nan"),
        "raw_relative_error": float(raw_err / true_rms) if true_rms > 0 else float("nan"),
        "masked_true_motion_share": float(energy[suppressed[ok]].sum() / energy.sum())
        if energy.sum() > 0
        else 0.0,
    }
