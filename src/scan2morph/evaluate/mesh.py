"""Accuracy of fitted meshes and of rigid alignment against ground truth."""

from __future__ import annotations

import numpy as np

from scan2morph.align.rigid import rotation_angle_deg
from scan2morph.evaluate.truth import Truth, closest_points


def mesh_accuracy(vertices: np.ndarray, valid: np.ndarray, truth: Truth) -> dict:
    """Distance of the valid vertices of a fitted mesh to the true surface.

    The true surface is the whole truth mesh: skin and the eyeballs, which a range scanner
    measures too (the template covers the eyes). The mouth cavity is in the mesh but returns no
    data, so no valid vertex is sampled from it.

    Parameters
    ----------
    vertices : (V, 3) float, mm, in the take's scanner frame
    valid : (V,) bool
    truth : Truth

    Returns
    -------
    dict
        ``rms_mm``, ``p95_mm``, ``max_mm`` of the distances and ``valid_share``.
    """
    pts = vertices[valid]
    _, _, dist = closest_points(truth.posed_vertices(), truth.faces, pts)
    return {
        "rms_mm": float(np.sqrt(np.mean(dist**2))),
        "p95_mm": float(np.percentile(dist, 95)),
        "max_mm": float(dist.max()),
        "valid_share": float(valid.mean()),
    }


def true_alignment(take: Truth, neutral: Truth) -> np.ndarray:
    """(4, 4) true transform from the take's scanner frame to the neutral's."""
    return neutral.pose @ np.linalg.inv(take.pose)


def alignment_accuracy(
    transform: np.ndarray, vertices: np.ndarray, valid: np.ndarray, take: Truth, neutral: Truth
) -> dict:
    """Rotation error (degrees) and translation error at the face centroid (mm) of an alignment.

    Parameters
    ----------
    transform : (4, 4) estimated take -> neutral transform
    vertices, valid : the take's mesh in its scanner frame (the centroid is of the valid vertices)
    """
    true = true_alignment(take, neutral)
    # atan2, not arccos: a 0.03 degree error is read to 1e-13, not to 1e-9 (arccos amplifies the
    # last bit of the trace by 1 / sin(angle))
    angle = rotation_angle_deg(transform[:3, :3].T @ true[:3, :3])
    c = vertices[valid].mean(axis=0)
    est = transform[:3, :3] @ c + transform[:3, 3]
    ref = true[:3, :3] @ c + true[:3, 3]
    return {"rotation_deg": float(angle), "translation_mm": float(np.linalg.norm(est - ref))}
