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
    transform: np.ndarray,
    take_pose: np.ndarray | None = None,
    neutral_pose: np.ndarray | None = None,
) -> float:
    """The angle between two takes' viewing directions once they are aligned, in degrees.

    A take's grid is its camera's view of the face; the neutral's, its own camera's. After the
    take's alignment (``transform``: take frame -> neutral frame) the two cameras' optical axes
    are compared in the neutral's frame: a head turned 20 degrees between the takes in front of
    a fixed scanner gives 20 whatever the turn's axis in the image plane, and a turn about the
    optical axis (the head tilted within the image) gives 0.

    Parameters
    ----------
    transform : (4, 4) float
        The take's alignment, take frame -> neutral frame, mm.
    take_pose, neutral_pose : (4, 4) float, optional
        Each take's frame -> its camera's frame (a mesh take's virtual camera, an RGB-D take's
        colour camera); None: the take's points are in its camera's frame (range, stereo).

    Returns
    -------
    float
        In [0, 180] degrees.
    """
    z = np.array([0.0, 0.0, 1.0])
    rotations = [
        np.eye(3) if p is None else _transform(p)[:3, :3] for p in (take_pose, neutral_pose)
    ]
    take_axis = _transform(transform)[:3, :3] @ (rotations[0].T @ z)  # in the neutral frame
    neutral_axis = rotations[1].T @ z
    cos = float(np.clip(take_axis @ neutral_axis, -1.0, 1.0))
    sin = float(np.linalg.norm(np.cross(take_axis, neutral_axis)))
    return float(np.degrees(np.arctan2(sin, cos)))


__all__ = ["invert", "kabsch", "rotation_angle_deg", "transform_points", "view_turn_deg"]
