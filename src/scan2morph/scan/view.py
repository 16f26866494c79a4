"""Where a range image was seen from (:func:`scanner_view`), estimated from its own pixel grid.

Scanner XYZ may come in any right-handed frame, but every pixel's point lies on its pixel's ray:
the camera that took the image follows from the data. The spike test and the depth-camera
cleanup of a range image (:mod:`scan2morph.scan.repair`) and the sampling of a range image at the
template's vertices (:mod:`scan2morph.template.sample`) take their rules in its frame.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy.linalg import rq

from scan2morph.geometry import finite_points, lambert_grey, surface_normals

#: A range image's estimated camera within this angle (deg) of the z axis and with its centre
#: within this share of the data's distance from the origin is taken to be in the conventional
#: scanner frame (scanner at the origin looking along +-z), exactly as given.
FRAME_SNAP_DEG = 5.0
FRAME_SNAP_SHARE = 0.05
#: Pixels used to estimate a range image's camera (a fixed subsample of the pixel grid).
_FRAME_PIXELS = 4000
#: Largest RMS reprojection error (px) of an estimated camera that is trusted.
_FRAME_MAX_RMS_PX = 0.5
#: The last estimates, keyed by a hash of the pixels and points they were fitted to: one job
#: samples one range image many times (a refinement's lip profiles, the click-noise draws), and
#: each sampler asks for its camera. The key is the estimate's whole input, so a hit returns
#: exactly what the fit would.
_ESTIMATES: OrderedDict[bytes, ScannerView] = OrderedDict()
_ESTIMATES_KEPT = 16


@dataclass(frozen=True)
class ScannerView:
    """Where a range image was seen from, in the range image's own frame.

    Attributes
    ----------
    centre : (3,) float64
        The camera centre, mm.
    axis : (3,) float64
        Unit optical axis (the depth direction; its sign does not matter).
    rotation : (3, 3) float64
        Rows: the camera's x (along the image rows), y and z (``axis``) directions, so that
        ``(xyz - centre) @ rotation.T`` is the camera frame (identity in the conventional one).
    estimated : bool
        True when estimated from the pixel grid; False for the conventional scanner frame
        (centre at the origin, axis z), used when the estimate agrees with it or is not
        determined (a plane, too few pixels, data that no pinhole camera explains).
    """

    centre: np.ndarray
    axis: np.ndarray
    rotation: np.ndarray
    estimated: bool = False


#: The conventional scanner frame: scanner at the origin looking along z.
SCANNER_FRAME = ScannerView(np.zeros(3), np.array([0.0, 0.0, 1.0]), np.eye(3))


def scanner_view(xyz: np.ndarray) -> ScannerView:
    """The camera that took a range image, estimated from its pixel grid.

    Scanner XYZ may come in any right-handed frame, but every pixel's point lies on that pixel's
    ray: the projection ``(column, row) ~ P (X, 1)`` is fitted to the valid pixels (a direct
    linear transform on a fixed subsample of the grid, coordinates normalised about their
    centroid so that the fit turns with the data), refitted without the pixels it explains
    worse than 3 times the median. Its centre is the camera centre, its third row the optical
    axis. A rigid motion of ``xyz`` moves the estimate with it.

    Returns :data:`SCANNER_FRAME` when the estimate is within :data:`FRAME_SNAP_DEG` of the
    z axis and its centre within :data:`FRAME_SNAP_SHARE` of the data's distance of the origin
    (so the conventional frame gives exactly the conventional rules), and when no pinhole camera
    is determined (fewer than 12 pixels, planar data, an affine view, RMS reprojection error
    above 0.5 px).

    The last few estimates are kept, keyed by the sampled pixels and their points: asking again
    for the same data (in any array) returns the same estimate without refitting it.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    h, w = xyz.shape[:2]
    ok = finite_points(xyz).reshape(-1)
    idx = np.flatnonzero(ok)
    if len(idx) < 12:
        return SCANNER_FRAME
    idx = idx[:: max(1, len(idx) // _FRAME_PIXELS)]
    X = xyz.reshape(-1, 3)[idx]
    key = hashlib.blake2b(
        np.int64(w).tobytes() + idx.tobytes() + X.tobytes(), digest_size=20
    ).digest()
    if key not in _ESTIMATES:
        _ESTIMATES[key] = _estimate(X, np.column_stack([idx % w, idx // w]).astype(np.float64))
        if len(_ESTIMATES) > _ESTIMATES_KEPT:
            _ESTIMATES.popitem(last=False)
    _ESTIMATES.move_to_end(key)
    return _ESTIMATES[key]


def _estimate(X: np.ndarray, uv: np.ndarray) -> ScannerView:
    """:func:`scanner_view`'s camera fitted to the points ``X`` (n, 3) mm seen at the pixels
    ``uv`` (n, 2) (column, row)."""
    keep = np.ones(len(X), dtype=bool)
    for _ in range(2):
        P, sv = _dlt(X[keep], uv[keep])
        if P is None or sv[-1] > 0.1 * sv[-2]:
            return SCANNER_FRAME  # not determined: planar or affine data
        err = _reprojection_px(P, X, uv)
        keep = err <= max(3.0 * float(np.median(err)), 1e-6)
        if keep.sum() < 12:
            return SCANNER_FRAME
    M, p4 = P[:, :3], P[:, 3]
    if np.linalg.cond(M) > 1e12 or np.sqrt(np.mean(err[keep] ** 2)) > _FRAME_MAX_RMS_PX:
        return SCANNER_FRAME
    centre = -np.linalg.solve(M, p4)
    if np.linalg.det(M) < 0:  # P is known up to its sign: take the one of a proper rotation
        M = -M
    upper, rotation = rq(M)
    rotation = np.sign(np.diag(upper))[:, None] * rotation  # K with a positive diagonal
    axis = rotation[2]
    dist = float(np.median(np.linalg.norm(X, axis=1)))
    if (
        np.degrees(np.arccos(min(abs(axis[2]), 1.0))) < FRAME_SNAP_DEG
        and np.linalg.norm(centre) < FRAME_SNAP_SHARE * dist
    ):
        return SCANNER_FRAME
    return ScannerView(centre, axis, rotation, estimated=True)


def _dlt(X: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
    """(3, 4) projection fitted to points ``X`` (n, 3) seen at pixels ``uv`` (n, 2), and the
    singular values of the normalised system (None when there are too few points)."""
    if len(X) < 12:
        return None, np.zeros(12)
    cx, cu = X.mean(axis=0), uv.mean(axis=0)
    sx = max(float(np.sqrt(np.mean(np.sum((X - cx) ** 2, axis=1)))), 1e-300)
    su = max(float(np.sqrt(np.mean(np.sum((uv - cu) ** 2, axis=1)))), 1e-300)
    Xn = np.column_stack([(X - cx) / sx, np.ones(len(X))])
    un = (uv - cu) / su
    zero = np.zeros_like(Xn)
    A = np.concatenate(
        [
            np.hstack([Xn, zero, -un[:, :1] * Xn]),
            np.hstack([zero, Xn, -un[:, 1:] * Xn]),
        ]
    )
    _, sv, vt = np.linalg.svd(A, full_matrices=False)
    Pn = vt[-1].reshape(3, 4)
    # undo the normalisation: u = su un + cu, Xn = (X - cx) / sx
    Tu = np.array([[su, 0.0, cu[0]], [0.0, su, cu[1]], [0.0, 0.0, 1.0]])
    Tx = np.eye(4)
    Tx[:3, :3] /= sx
    Tx[:3, 3] = -cx / sx
    return Tu @ Pn @ Tx, sv


def _reprojection_px(P: np.ndarray, X: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(n,) distance, px, between ``uv`` and the projections of ``X`` by ``P``."""
    h = X @ P[:, :3].T + P[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        proj = h[:, :2] / h[:, 2:]
    err = np.linalg.norm(proj - uv, axis=1)
    return np.where(np.isfinite(err), err, np.inf)


__all__ = ["FRAME_SNAP_DEG", "FRAME_SNAP_SHARE", "SCANNER_FRAME", "ScannerView", "scanner_view"]


def shaded_image(xyz: np.ndarray) -> np.ndarray:
    """A geometry-only range image shown by its shading: grey, lit from the scanner.

    Lambert's law with the light at the scanner, as a geometry-only mesh scan is shown
    (:func:`scan2morph.io.mesh_scan.shade`): each pixel's grey is
    ``SHADE_AMBIENT + (1 - SHADE_AMBIENT) * |n . a|`` of full white, ``n`` the surface's unit
    normal there and ``a`` the scanner's optical axis (:func:`scanner_view`); black where there
    is no data.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data

    Returns
    -------
    (H, W, 3) uint8
    """
    grey = lambert_grey(surface_normals(xyz) @ scanner_view(xyz).axis)
    return np.repeat(grey[..., None], 3, axis=2)
