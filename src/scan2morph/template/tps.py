"""Thin-plate-spline warp of the template plane onto the image (Yano-Harada 3.1).

F(u) = A(u) + sum_i lambda_i phi(|u - u_i|) with phi(r) = r^2 log r and A affine, solved as the
paper's linear system ::

    [ Phi  P ] [lambda]   [v]
    [ P^T  0 ] [  a   ] = [0]

where Phi_ij = phi(|u_i - u_j|) and P = [1, u_x, u_y]. The warp interpolates the fiducials
exactly; the number of unknowns depends only on the number of fiducials.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError
from scan2morph.tol import RCOND

#: Points a warp's product with the weights takes at once (its rounding depends on them).
BLOCK = 65536
#: Points whose kernel values are computed at once (temporaries of a few MB).
CHUNK = 4096


def _phi(r: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        out = r * r * np.log(r)
    return np.where(r > 0, out, 0.0)


def _pairwise(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (n, m) between the 2D points ``a`` (n, 2) and ``b`` (m, 2), by coordinate:
    no (n, m, 2) temporary (a template's vertices against the fiducials are millions)."""
    dx = a[:, None, 0] - b[None, :, 0]
    dy = a[:, None, 1] - b[None, :, 1]
    return np.sqrt(dx * dx + dy * dy)


def _system(src: np.ndarray) -> np.ndarray:
    """The (m + 3, m + 3) matrix ``[[Phi, P], [P^T, 0]]`` of the spline through ``src``."""
    m = len(src)
    p = np.column_stack([np.ones(m), src])
    a = np.zeros((m + 3, m + 3))
    a[:m, :m] = _phi(_pairwise(src, src))
    a[:m, m:] = p
    a[m:, :m] = p.T
    return a


@dataclass(frozen=True)
class TPS:
    """A fitted 2D thin-plate spline.

    Attributes
    ----------
    centres : (m, 2) float64
        Source points u_i (template coordinates).
    weights : (m, 2) float64
        lambda_i for x and y.
    affine : (3, 2) float64
        Coefficients of A(u) = a0 + a1 u_x + a2 u_y for x and y.
    """

    centres: np.ndarray
    weights: np.ndarray
    affine: np.ndarray

    @classmethod
    def fit(cls, src, dst, source: str = "tps", image_size: tuple[int, int] | None = None) -> TPS:
        """Solve for the spline mapping ``src`` (m, 2) onto ``dst`` (m, 2).

        Parameters
        ----------
        src, dst : (m, 2) float
            Fiducials in the template frame and their image positions (pixels).
        source : str
            Label for error messages (``subject/take``).
        image_size : (width, height), optional
            When given, ``dst`` points must lie inside the image.

        Raises
        ------
        InputError
            Fewer than 3 points, non-finite points, duplicate points, all points collinear
            (singular system), image points that all coincide or lie on one line, or
            destination points outside the image.
        """
        src = np.asarray(src, dtype=np.float64)
        dst = np.asarray(dst, dtype=np.float64)
        if src.ndim != 2 or src.shape[1] != 2 or dst.shape != src.shape:
            raise InputError(
                source, f"fiducials: expected two (m, 2) arrays, got {src.shape} and {dst.shape}"
            )
        m = len(src)
        if m < 3:
            raise InputError(
                source, f"fiducials: a thin-plate spline needs at least 3 points, got {m}"
            )
        for name, pts in (("template", src), ("image", dst)):
            bad = ~np.isfinite(pts).all(axis=1)
            if bad.any():
                raise InputError(
                    source, f"fiducials: {name} point {int(np.argmax(bad))} is not finite"
                )
        d = _pairwise(src, src)
        scale = max(float(np.ptp(src, axis=0).max()), 1e-300)
        i, j = np.nonzero(np.triu(d <= 1e-9 * scale, k=1))
        if len(i):
            raise InputError(
                source, f"fiducials: points {int(i[0])} and {int(j[0])} coincide (duplicate points)"
            )
        centred = src - src.mean(axis=0)
        sv = np.linalg.svd(centred, compute_uv=False)
        if sv[1] <= RCOND * 1e2 * max(sv[0], 1e-300):
            raise InputError(
                source, "fiducials: all points are collinear (the spline's system is singular)"
            )
        dst_spread = np.linalg.svd(dst - dst.mean(axis=0), compute_uv=False)
        if dst_spread[1] <= 1e-3 * max(dst_spread[0], 1e-300) or dst_spread[0] < 1e-6:
            what = "all coincide" if dst_spread[0] < 1e-6 else "all lie on one line"
            raise InputError(
                source,
                f"fiducials: the image points {what} (at {dst.mean(axis=0).round(1).tolist()}); "
                "expected landmarks spread over a face",
            )
        if image_size is not None:
            w, h = image_size
            out = (
                (dst[:, 0] < -0.5)
                | (dst[:, 0] > w - 0.5)
                | (dst[:, 1] < -0.5)
                | (dst[:, 1] > h - 0.5)
            )
            if out.any():
                k = int(np.argmax(out))
                raise InputError(
                    source,
                    f"fiducials: image point {k} at {dst[k].round(1).tolist()} is outside the {w}x{h} image",
                )
        b = np.zeros((m + 3, 2))
        b[:m] = dst
        try:
            x = np.linalg.solve(_system(src), b)
        except np.linalg.LinAlgError:
            raise InputError(source, "fiducials: singular thin-plate spline system") from None
        return cls(centres=src, weights=x[:m], affine=x[m:])

    def __call__(self, points) -> np.ndarray:
        """Warp points (n, 2) -> (n, 2); vectorised in blocks of :data:`BLOCK` points to bound
        memory, each block's kernel values computed :data:`CHUNK` points at a time (their
        temporaries stay in the cache: twice as fast on a refinement's grid, and the same
        values; the product with the weights stays one per block, whose rounding depends on
        the block's rows)."""
        pts = np.asarray(points, dtype=np.float64)
        out = np.empty_like(pts)
        for s in range(0, len(pts), BLOCK):
            blk = pts[s : s + BLOCK]
            kernel = np.empty((len(blk), len(self.centres)))
            for c in range(0, len(blk), CHUNK):
                kernel[c : c + CHUNK] = _phi(_pairwise(blk[c : c + CHUNK], self.centres))
            out[s : s + BLOCK] = self.affine[0] + blk @ self.affine[1:] + kernel @ self.weights
        return out


def tps_warp(src, dst, points, source: str = "tps", image_size=None) -> np.ndarray:
    """Fit the spline taking ``src`` to ``dst`` and apply it to ``points`` (n, 2)."""
    return TPS.fit(src, dst, source=source, image_size=image_size)(points)


def noise_gain(src, points) -> np.ndarray:
    """How much of the fiducials' position noise a spline passes on to warped points.

    The warp is linear in the destination points: ``F(p) = sum_i L_i(p) v_i`` with weights
    ``L_i(p)`` that sum to one. Independent noise of standard deviation ``s`` on every
    destination coordinate moves ``F(p)`` by ``s * sqrt(sum_i L_i(p)^2)`` per coordinate; this
    returns that factor. It is 1 at a fiducial, below 1 between well-spread fiducials and above
    1 where the spline extrapolates or where two fiducials nearly coincide.

    Parameters
    ----------
    src : (m, 2) float
        Fiducials in the template frame (validated as by :meth:`TPS.fit`).
    points : (n, 2) float
        Template points to warp.

    Returns
    -------
    (n,) float64
        The noise gain at each point.
    """
    src = np.asarray(src, dtype=np.float64)
    m = len(src)
    TPS.fit(src, src, source="noise_gain")  # the same checks as a fit
    rhs = np.zeros((m + 3, m))
    rhs[:m] = np.eye(m)
    x = np.linalg.solve(_system(src), rhs)  # column k: the spline taking e_k to 1, others to 0
    pts = np.asarray(points, dtype=np.float64)
    weights = np.column_stack([np.ones(len(pts)), pts]) @ x[m:] + _phi(_pairwise(pts, src)) @ x[:m]
    return np.sqrt(np.sum(weights**2, axis=1))
