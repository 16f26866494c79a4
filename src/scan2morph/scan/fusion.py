"""Several depth frames of one RGB-D take fused into one depth image.

A depth camera's single frame is noisy (millimetres at a metre, growing with the square of the
distance). A take may therefore bring several frames of the same pose; the subject moves a little
between them (breathing, a head that is not held), so the frames are first registered and then
averaged:

1. **Reference.** The first frame is the one the colour image was taken with: the fused depth
   lies on its grid, in its camera frame.
2. **Registration.** Each other frame is registered rigidly onto the reference by projective
   point-to-plane ICP (each of its points paired with the reference pixel it projects to, the
   data association of depth-camera tracking): Gauss-Newton steps of a linearised rotation and
   translation, weighted by a Tukey kernel whose scale halves from ``max_pair_mm`` to three
   robust standard deviations of the residuals.
3. **Resampling.** Each registered frame's triangulated surface is rasterised into the
   reference camera (:func:`scan2morph.io.rgbd.surface_on_camera`), giving per reference pixel
   one depth per frame along the same ray.
4. **Averaging.** Per pixel, the depths within ``outlier_sigmas`` robust standard deviations
   (over the whole image) of the pixel's median are averaged when at least half of the frames
   agree so; otherwise (frames that disagree: a background that did not move with the head, a
   flying pixel) the reference frame's own depth is kept, as the colour image saw it.

A frame that does not register (too few pairs, a motion beyond ``max_motion_deg`` /
``max_motion_mm``, no convergence) is refused naming the frame: frames of another take or a
subject who turned away cannot be averaged.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from scan2morph.errors import InputError
from scan2morph.geometry import surface_normals
from scan2morph.io.rgbd import PinholeCamera, depth_points, project_points, surface_on_camera
from scan2morph.scan.depth_cleanup import smooth_depth
from scan2morph.tol import MAD_TO_SIGMA

#: Points of a frame used for its registration (a regular subsample), at most.
MAX_POINTS = 40_000
#: The reference's normals are taken from it smoothed by this Gaussian, px, across depth steps
#: below ``SMOOTH_JUMP_MM`` (:func:`scan2morph.scan.depth_cleanup.smooth_depth`).
SMOOTH_PX = 2.0
SMOOTH_JUMP_MM = 10.0
#: Tukey kernel scale never below this, mm.
MIN_KERNEL_MM = 0.5
#: Registration stops when a step turns less than this (radians) and moves less than
#: ``STEP_MM``.
STEP_RAD = 1e-6
STEP_MM = 1e-4
#: A registration pairs at least this share of the frame's points with the reference.
MIN_FITNESS = 0.5


@dataclass(frozen=True)
class FusionParams:
    """How frames are registered and averaged.

    Attributes
    ----------
    max_pair_mm : float
        Largest distance of a pair in the registration, mm (the first kernel scale).
    iterations : int
        Registration steps at most.
    max_motion_deg, max_motion_mm : float
        Largest motion of a frame from the reference accepted, degrees and mm.
    outlier_sigmas : float
        A frame's depth farther from the pixel's median than this many robust standard
        deviations is left out of the average.
    foreground_mm : float
        Only the surface within this depth behind the nearest one (a face, not the wall behind
        it, which stands still while the head moves) is registered, mm.
    """

    max_pair_mm: float = 8.0
    iterations: int = 40
    max_motion_deg: float = 10.0
    max_motion_mm: float = 30.0
    outlier_sigmas: float = 3.0
    foreground_mm: float = 250.0


@dataclass(frozen=True)
class FusedDepth:
    """The fused depth image and how each frame was registered.

    Attributes
    ----------
    depth_mm : (H, W) float64
        Depth on the reference frame's grid, mm; NaN without data.
    transforms : (N, 4, 4) float64
        Frame ``k`` -> reference frame, mm (``transforms[0]`` is the identity).
    rmse_mm : (N,) float64
        Robust point-to-plane RMSE of each frame's registration, mm (0 for the reference).
    fitness : (N,) float64
        Share of each frame's points paired with the reference (1 for the reference).
    count : (H, W) int64
        Frames averaged at each pixel (1 where the reference's own depth was kept, 0 without
        data).
    """

    depth_mm: np.ndarray
    transforms: np.ndarray
    rmse_mm: np.ndarray
    fitness: np.ndarray
    count: np.ndarray

    @property
    def motion_deg(self) -> np.ndarray:
        """(N,) rotation of each frame from the reference, degrees."""
        return np.degrees(Rotation.from_matrix(self.transforms[:, :3, :3]).magnitude())

    @property
    def motion_mm(self) -> np.ndarray:
        """(N,) translation of each frame from the reference, mm."""
        return np.linalg.norm(self.transforms[:, :3, 3], axis=1)


def fuse_depth_frames(
    frames: Sequence[np.ndarray],
    camera: PinholeCamera,
    sources: Sequence[str],
    params: FusionParams | None = None,
) -> FusedDepth:
    """Register several depth frames of one take onto the first and average them.

    Parameters
    ----------
    frames : sequence of (H, W) float
        Depth (camera Z) of each frame, mm; 0 or NaN = no data. The first is the reference.
    camera : PinholeCamera
        The depth camera (every frame's).
    sources : sequence of str
        Each frame's file, for messages.
    params : FusionParams, optional

    Returns
    -------
    FusedDepth

    Raises
    ------
    InputError
        Frames of different sizes or not the camera's; a frame that does not register onto the
        reference (names the frame, the share of points paired and the motion found).
    """
    prm = params or FusionParams()
    if len(frames) != len(sources) or not frames:
        raise InputError("depth frames", "expected one source name per frame, at least one frame")
    size = (camera.size[1], camera.size[0])
    for depth, src in zip(frames, sources, strict=True):
        if np.shape(depth) != size:
            raise InputError(src, f"depth: expected {size[1]}x{size[0]} px, got {np.shape(depth)}")
    pts = [depth_points(np.nan_to_num(np.asarray(d, float)), camera) for d in frames]
    # the normals from the reference smoothed (differences of noisy neighbours point anywhere);
    # the points stay as measured (smoothing flattens the nose tip: a bias, not noise)
    ref = _foreground(pts[0], prm.foreground_mm)
    ref_normals = surface_normals(smooth_depth(pts[0], SMOOTH_PX, SMOOTH_JUMP_MM))
    focal = float(camera.K[0, 0])
    transforms = [np.eye(4)]
    rmse, fitness = [0.0], [1.0]
    stack = [pts[0][..., 2]]
    for frame, src in zip(pts[1:], sources[1:], strict=True):
        near = _foreground(frame, prm.foreground_mm + prm.max_motion_mm)
        t, fit, err = register_frame(near, ref, ref_normals, camera, prm, src)
        transforms.append(t)
        rmse.append(err)
        fitness.append(fit)
        stack.append(surface_on_camera(frame, focal, camera, t)[..., 2])
    depth, count = _average(np.stack(stack), prm.outlier_sigmas)
    return FusedDepth(depth, np.stack(transforms), np.array(rmse), np.array(fitness), count)


def register_frame(
    frame: np.ndarray,
    ref: np.ndarray,
    ref_normals: np.ndarray,
    camera: PinholeCamera,
    params: FusionParams,
    source: str,
) -> tuple[np.ndarray, float, float]:
    """Projective point-to-plane ICP of one frame's points onto the reference grid.

    Parameters
    ----------
    frame, ref : (H, W, 3) float
        The frame's and the reference's points in their cameras' frames, mm; NaN without data.
    ref_normals : (H, W, 3) float
        The reference's unit normals (:func:`scan2morph.geometry.surface_normals`).
    camera : PinholeCamera
    params : FusionParams
    source : str
        The frame's file, for messages.

    Returns
    -------
    transform : (4, 4) float64
        Frame -> reference, mm.
    fitness : float
        Share of the frame's points paired at the end.
    rmse : float
        Robust point-to-plane RMSE of the kept pairs, mm.

    Raises
    ------
    InputError
        Fewer than half of the points paired, or a motion beyond the limits.
    """
    p = frame.reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    p = p[:: max(1, len(p) // MAX_POINTS)]
    t = np.eye(4)
    kernel = params.max_pair_mm
    fit, err = 0.0, np.inf
    for _ in range(params.iterations):
        moved = p @ t[:3, :3].T + t[:3, 3]
        q, n, paired = _pairs(moved, ref, ref_normals, camera, params)
        fit = paired.mean() if len(paired) else 0.0
        if fit < MIN_FITNESS:
            break
        moved = moved[paired]
        r = np.einsum("ij,ij->i", moved - q, n)
        sigma = MAD_TO_SIGMA * float(np.median(np.abs(r)))
        kernel = max(kernel / 2.0, 3.0 * sigma, MIN_KERNEL_MM)
        w = np.where(np.abs(r) < kernel, (1.0 - (r / kernel) ** 2) ** 2, 0.0)
        err = float(np.sqrt(np.sum(w * r**2) / max(np.sum(w), 1e-300)))
        step = _gauss_newton(moved, n, r, w)
        t = step @ t
        if np.linalg.norm(Rotation.from_matrix(step[:3, :3]).as_rotvec()) < STEP_RAD and (
            np.linalg.norm(step[:3, 3]) < STEP_MM
        ):
            break
    angle = float(np.degrees(Rotation.from_matrix(t[:3, :3]).magnitude()))
    shift = float(np.linalg.norm(t[:3, 3]))
    if fit < MIN_FITNESS or angle > params.max_motion_deg or shift > params.max_motion_mm:
        raise InputError(
            source,
            f"depth: this frame does not register onto the take's first frame ({fit:.0%} of its "
            f"points paired, expected >= {MIN_FITNESS:.0%}; motion {angle:.1f} degrees, "
            f"{shift:.1f} mm, expected <= {params.max_motion_deg:g} degrees, "
            f"{params.max_motion_mm:g} mm): is it a frame of this take?",
        )
    return t, float(fit), err


def _foreground(pts: np.ndarray, depth_mm: float) -> np.ndarray:
    """``pts`` (H, W, 3) with the points farther than ``depth_mm`` behind the nearest surface
    (its 0.5th depth percentile) set to NaN."""
    z = pts[..., 2]
    if not np.isfinite(z).any():
        return pts
    near = float(np.nanpercentile(z, 0.5))
    return np.where((z <= near + depth_mm)[..., None], pts, np.nan)


def _pairs(moved, ref, ref_normals, camera: PinholeCamera, params: FusionParams):
    """Each moved point's reference point and normal at the pixel it projects to."""
    h, w = ref.shape[:2]
    front = moved[:, 2] > 0
    pix = np.full((len(moved), 2), -1.0)
    pix[front] = project_points(camera, moved[front])
    u, v = np.rint(pix[:, 0]).astype(np.int64), np.rint(pix[:, 1]).astype(np.int64)
    inside = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    idx = np.flatnonzero(inside)
    q, n = ref[v[idx], u[idx]], ref_normals[v[idx], u[idx]]
    ok = np.isfinite(q).all(axis=1) & np.isfinite(n).all(axis=1)
    ok &= np.linalg.norm(moved[idx] - q, axis=1) < params.max_pair_mm
    paired = np.zeros(len(moved), bool)
    paired[idx[ok]] = True
    return q[ok], n[ok], paired


def _gauss_newton(p: np.ndarray, n: np.ndarray, r: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(4, 4) the rigid step that minimises sum w ((R p + t - q) . n)^2, linearised in the
    rotation (``r`` = current residuals along ``n``)."""
    jac = np.column_stack([np.cross(p, n), n])  # d r / d (omega, t)
    a = jac.T @ (jac * w[:, None])
    b = -jac.T @ (w * r)
    x = np.linalg.lstsq(a, b, rcond=None)[0]
    step = np.eye(4)
    step[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
    step[:3, 3] = x[3:]
    return step


def _average(z: np.ndarray, outlier_sigmas: float) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel the mean of the depths near the median, (H, W) mm, and their count."""
    n = len(z)
    if n == 1:
        ok = np.isfinite(z[0])
        return np.where(ok, z[0], np.nan), ok.astype(np.int64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # pixels without any data: NaN
        median = np.nanmedian(z, axis=0)
    dev = np.abs(z - median)
    shared = np.isfinite(z).sum(axis=0) >= 2  # a pixel seen once says nothing of the noise
    finite = dev[:, shared][np.isfinite(dev[:, shared])]
    sigma = MAD_TO_SIGMA * float(np.median(finite)) if finite.size else 0.0
    keep = np.isfinite(z) & (dev <= max(outlier_sigmas * sigma, 1e-9))
    count = keep.sum(axis=0)
    total = np.where(keep, z, 0.0).sum(axis=0)
    enough = count >= (n + 1) // 2
    depth = np.where(enough, total / np.maximum(count, 1), np.nan)
    # where the frames disagree (a background that did not move with the head, a face that
    # did not move rigidly) the reference frame, the colour image's, is kept as it is
    alone = ~enough & np.isfinite(z[0])
    depth[alone] = z[0][alone]
    return depth, np.where(enough, count, alone.astype(np.int64)).astype(np.int64)


__all__ = ["FusedDepth", "FusionParams", "fuse_depth_frames", "register_frame"]
