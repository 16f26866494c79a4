"""Rigid transforms: least-squares fit (Kabsch), application, inversion, rotation angle, and
the turn between two takes' views.

A rigid transform is a (4, 4) float64 homogeneous matrix that maps column vectors,
``p_dst = T @ [p_src, 1]``. Rotations are proper (det +1); there is no scale.
"""

from __future__ import annotations

import numpy as np

from scan2morph.errors import InputError
from scan2morph.tol import RCOND


def _points(a: np.ndarray, name: str, source: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(source, f"{name}: expected (n, 3) points, got shape {a.shape}")
    return a


def kabsch(
    src: np.ndarray,
    dst: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    source: str = "kabsch",
) -> np.ndarray:
    """Least-squares rigid transform (rotation + translation, no scale) mapping src onto dst.

    Minimises ``sum_i w_i * ||R @ src_i + t - dst_i||^2`` over proper rotations R
    (det +1; a reflection in the cross-covariance is corrected, not returned) and t.

    Parameters
    ----------
    src, dst : (n, 3) float, mm
        Corresponding points, n >= 3, finite.
    weights : (n,) float, optional
        Non-negative weights; at least 3 must be positive. Default: all ones.
    source : str
        Label used in error messages (a file or ``subject/take``).

    Returns
    -------
    T : (4, 4) float64
        Homogeneous transform with ``dst ~ T @ [src, 1]``.

    Raises
    ------
    InputError
        Fewer than 3 points, shape mismatch, non-finite values, bad weights, or points that
        are collinear or coincident (the rotation is then not determined).
    """
    src = _points(src, "src", source)
    dst = _points(dst, "dst", source)
    if src.shape != dst.shape:
        raise InputError(source, f"dst: expected the shape of src {src.shape}, got {dst.shape}")
    n = src.shape[0]
    if n < 3:
        raise InputError(source, f"points: expected at least 3 point pairs, got {n}")
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        raise InputError(source, "points: expected finite coordinates, got NaN or inf")
    if weights is None:
        w = np.ones(n)
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n,):
            raise InputError(source, f"weights: expected shape ({n},), got {w.shape}")
        if not np.isfinite(w).all() or (w < 0).any():
            raise InputError(source, "weights: expected finite non-negative values")
        if np.count_nonzero(w) < 3:
            raise InputError(
                source, f"weights: expected at least 3 positive weights, got {np.count_nonzero(w)}"
            )
    w_sum = w.sum()
    c_src = w @ src / w_sum
    c_dst = w @ dst / w_sum
    sw = np.sqrt(w)[:, None]
    a = (src - c_src) * sw
    b = (dst - c_dst) * sw
    for name, m in (("src", a), ("dst", b)):
        s = np.linalg.svd(m, compute_uv=False)
        if s[0] == 0.0 or s[1] <= RCOND * s[0]:
            raise InputError(
                source,
                f"{name}: points are collinear or coincident (rank-deficient); "
                "expected at least 3 non-collinear points",
            )
    # Cross-covariance H = A^T B; R = V diag(1, 1, d) U^T with d fixing the handedness.
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    if d == 0.0:
        d = 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    t = np.eye(4)
    t[:3, :3] = r
    t[:3, 3] = c_dst - r @ c_src
    return t


def _transform(t: np.ndarray, source: str = "transform") -> np.ndarray:
    t = np.asarray(t, dtype=np.float64)
    if t.shape != (4, 4):
        raise InputError(source, f"transform: expected shape (4, 4), got {t.shape}")
    if not np.isfinite(t).all():
        raise InputError(source, "transform: expected finite values")
    return t


def transform_points(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Apply a rigid (or any affine) transform to points.

    Parameters
    ----------
    t : (4, 4) float
        Homogeneous transform.
    p : (..., 3) float, mm
        Points; NaN rows stay NaN.

    Returns
    -------
    (..., 3) float64, mm
        ``R @ p + t`` for each point.
    """
    t = _transform(t)
    p = np.asarray(p, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise InputError("transform", f"points: expected shape (..., 3), got {p.shape}")
    return p @ t[:3, :3].T + t[:3, 3]


def invert(t: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform, ``[R^T, -R^T t]`` (exact for rigid, no matrix inverse).

    Parameters
    ----------
    t : (4, 4) float
        Rigid transform.

    Returns
    -------
    (4, 4) float64
    """
    t = _transform(t)
    r = t[:3, :3]
    out = np.eye(4)
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ t[:3, 3]
    return out


def rotation_angle_deg(r: np.ndarray) -> float:
    """Rotation angle of a rotation matrix, in degrees (for reports).

    Parameters
    ----------
    r : (3, 3) or (4, 4) float
        Rotation matrix, or a rigid transform whose rotation block is used.

    Returns
    -------
    float
        Angle in [0, 180] degrees, from ``atan2(|axis|, (trace - 1) / 2)`` (accurate near
        0 and 180 degrees, unlike ``arccos``).
    """
    r = np.asarray(r, dtype=np.float64)
    if r.shape == (4, 4):
        r = r[:3, :3]
    if r.shape != (3, 3):
        raise InputError("rotation", f"R: expected shape (3, 3) or (4, 4), got {r.shape}")
    if not np.isfinite(r).all():
        raise InputError("rotation", "R: expected finite values")
    cos = (np.trace(r) - 1.0) / 2.0
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    sin = np.linalg.norm(axis) / 2.0
    return float(np.degrees(np.arctan2(sin, cos)))


def view_turn_deg(
    transform: np.ndarray, take_camera: np.ndarray, neutral_camera: np.ndarray, face: np.ndarray
) -> float:
    """How far a take's camera stood from its neutral's, as the face sees them: the angle at
    ``face`` between the directions to the two camera centres once the take is aligned, in
    degrees.

    A head turned 20 degrees between the takes in front of a fixed scanner gives 20 (about any
    axis through the face); a head that only tilts within the image, or turns about the
    camera's own centre, shows the camera the same side of the face and gives 0; a head moved
    sideways gives the angle it moved by as the face sees it.

    Parameters
    ----------
    transform : (4, 4) float
        The take's alignment, take frame -> neutral frame, mm.
    take_camera : (3,) float
        The take's camera centre in the take's frame, mm.
    neutral_camera : (3,) float
        The neutral's camera centre in the neutral's frame, mm.
    face : (3,) float
        A point of the face in the neutral's frame (its centre), mm.

    Returns
    -------
    float
        In [0, 180] degrees.
    """
    t = _transform(transform)
    points = [np.asarray(p, dtype=np.float64) for p in (take_camera, neutral_camera, face)]
    for name, p in zip(("take_camera", "neutral_camera", "face"), points, strict=True):
        if p.shape != (3,) or not np.isfinite(p).all():
            raise InputError("view turn", f"{name}: expected 3 finite coordinates, got {p}")
    a = t[:3, :3] @ points[0] + t[:3, 3] - points[2]
    b = points[1] - points[2]
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)))


__all__ = ["invert", "kabsch", "rotation_angle_deg", "transform_points", "view_turn_deg"]
