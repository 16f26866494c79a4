"""Dense stereo reconstruction: a calibrated image pair to an organised range image.

The pipeline (OpenCV throughout):

1. **rectify** both images (:func:`cv2.stereoRectify` with zero disparity at infinity, then
   :func:`cv2.initUndistortRectifyMap` / :func:`cv2.remap`), keeping every source pixel
   (``alpha = 1``) at the source resolution (the rectified canvas grows instead);
2. **dense disparity** by semi-global matching (:func:`cv2.StereoSGBM_create`, 1/16 px) of the
   left view and of the right view (:func:`cv2.ximgproc.createRightMatcher`), on a canvas padded
   so that SGBM's unmatched border bands hold no image content;
3. a **left-right consistency check** (the two disparities must agree within
   ``lr_max_diff_px``); optionally opencv-contrib's WLS filter
   (:func:`cv2.ximgproc.createDisparityWLSFilter`), still masked by the check because WLS fills
   holes with guesses; pixels without local texture are dropped (SGM propagates guesses into
   them);
4. **sub-pixel refinement** of SGBM's disparity by windowed Gauss-Newton on locally normalised
   images (removes the pixel-locking bias of SGBM's parabola fit); then the band around depth
   discontinuities, where window matching adheres the wrong side, and one pixel along every
   hole border (mixed pixels) are dropped;
5. **resampling into the unrectified left image grid**: every left pixel is mapped to its
   rectified position (:func:`cv2.undistortPoints` with ``R=R1, P=P1``), the disparity is
   interpolated bilinearly there (only where all four neighbours are valid and within
   ``max_step_px``), the point ``Q @ (u, v, d, 1)`` (what :func:`cv2.reprojectImageTo3D`
   computes per pixel) is formed and rotated back from the rectified into the unrectified left
   camera frame (``R1^T``).

The result is the organised range image of a range scan, pixel to pixel with the left color
image: ``xyz[y, x]`` lies on the (undistorted) ray of left pixel ``(x, y)``.

Interpolating the disparity rather than the rectified XYZ is deliberate: disparity is an affine
function of the rectified pixel on a plane, so the interpolation is exact for planar patches and
the point stays exactly on the pixel's ray.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from os import PathLike
from typing import Any

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.calibration import StereoCalibration, validate_stereo_calibration

#: Default parameters of :func:`reconstruct_stereo`. SGBM parameters carry OpenCV's names
#: (see :func:`cv2.StereoSGBM_create`); ``None`` means "derive it" as documented there.
DEFAULT_STEREO: dict[str, Any] = {
    # disparity search range: derived from the expected depth range unless given
    "min_depth_mm": 400.0,  # nearest expected surface, mm
    "max_depth_mm": 1500.0,  # farthest expected surface, mm
    "minDisparity": None,  # px; None: from max_depth_mm
    "numDisparities": None,  # px, multiple of 16; None: from min_depth_mm
    # semi-global matching (on the grey images)
    "blockSize": 5,  # odd, px
    "P1": None,  # None: 8 * blockSize**2 (OpenCV's recommendation for one channel)
    "P2": None,  # None: 32 * blockSize**2
    "uniquenessRatio": 10,  # %
    "speckleWindowSize": 100,  # px; 0 disables the speckle filter
    "speckleRange": 2,  # px of disparity within a speckle
    "preFilterCap": 63,
    "mode": "sgbm_3way",  # "sgbm" (5 paths), "hh" (8 paths), "sgbm_3way", "hh4"
    # post-processing
    "lr_max_diff_px": 1.0,  # left-right check: largest disagreement of the two views, px
    "refine_iterations": 3,  # Gauss-Newton sub-pixel refinement steps; 0 keeps SGBM's 1/16 px
    "refine_sigma_px": 2.0,  # Gaussian window of the refinement and texture check, px
    "min_texture": 2.0,  # least local grey-level std in the left view; flat areas are guesses
    "min_zncc": 0.0,  # reject matches whose windowed ZNCC after refinement is lower
    "edge_trim_px": 4,  # drop matches within this radius of a depth discontinuity, px
    "edge_jump_px": 8.0,  # a discontinuity: disparity range above this within the radius, px
    "erode_px": 1,  # drop valid pixels this close to an invalid one (mixed pixels), px
    "wls": False,  # WLS smoothing (measured on speckle: depth RMS 0.35 -> 0.45 mm, worse)
    "wls_lambda": 8000.0,
    "wls_sigma_color": 1.5,
    "max_step_px": 1.0,  # largest disparity spread of the 4 neighbours interpolated, px
    # rectification
    "rectify_alpha": 1.0,  # cv2.stereoRectify's alpha: 1 keeps every source pixel
    "max_upscale": 1.5,  # the rectified image may grow by this factor to keep resolution
    # sanity
    "min_coverage": 0.05,  # fewest left pixels with a point, as a fraction of the image
}

_MODES = {
    "sgbm": cv2.STEREO_SGBM_MODE_SGBM,
    "hh": cv2.STEREO_SGBM_MODE_HH,
    "sgbm_3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    "hh4": cv2.STEREO_SGBM_MODE_HH4,
}


def stereo_params(
    params: Mapping[str, Any] | None = None, source: str = "params"
) -> dict[str, Any]:
    """:data:`DEFAULT_STEREO` updated with ``params``, checked.

    Raises
    ------
    InputError
        An unknown key, or a value out of range (names the key).
    """
    p = dict(DEFAULT_STEREO)
    for key, value in (params or {}).items():
        if key not in p:
            raise InputError(source, f"{key}: unknown stereo parameter (known: {', '.join(p)})")
        p[key] = value
    if not 0 < p["min_depth_mm"] < p["max_depth_mm"]:
        raise InputError(
            source,
            f"min_depth_mm, max_depth_mm: expected 0 < min < max, "
            f"got {p['min_depth_mm']}, {p['max_depth_mm']}",
        )
    if p["numDisparities"] is not None and (p["numDisparities"] <= 0 or p["numDisparities"] % 16):
        raise InputError(
            source, f"numDisparities: expected a positive multiple of 16, got {p['numDisparities']}"
        )
    if p["blockSize"] < 1 or p["blockSize"] % 2 == 0:
        raise InputError(source, f"blockSize: expected an odd number >= 1, got {p['blockSize']}")
    if p["mode"] not in _MODES:
        raise InputError(source, f"mode: expected one of {', '.join(_MODES)}, got {p['mode']!r}")
    if p["lr_max_diff_px"] <= 0 or p["max_step_px"] <= 0:
        raise InputError(source, "lr_max_diff_px, max_step_px: expected positive values")
    if not 0 <= p["rectify_alpha"] <= 1 or p["max_upscale"] < 1:
        raise InputError(source, "rectify_alpha: expected [0, 1]; max_upscale: expected >= 1")
    if not 0 <= p["min_coverage"] < 1:
        raise InputError(
            source, f"min_coverage: expected a fraction in [0, 1), got {p['min_coverage']}"
        )
    return p


def reconstruct_stereo(
    left: np.ndarray,
    right: np.ndarray,
    calib: StereoCalibration,
    params: Mapping[str, Any] | None = None,
    source: str | PathLike[str] = "stereo",
) -> tuple[np.ndarray, dict[str, Any]]:
    """Reconstruct the organised range image of a calibrated stereo pair.

    Parameters
    ----------
    left, right : (H, W, 3) uint8 or (H, W) uint8
        RGB (or grey) images of the left (first) and right (second) camera, raw (distorted).
    calib : StereoCalibration
        The rig: ``x2 = R x1 + T``, mm. Its ``image_size``, if given, must be ``(W, H)``.
    params : mapping, optional
        Overrides of :data:`DEFAULT_STEREO`.
    source : str or path-like
        Label (e.g. the left image file or ``subject/take``) named in errors.

    Returns
    -------
    xyz : (H, W, 3) float64
        Point of every left pixel in the unrectified left camera frame, mm; NaN where there is
        no data. ``xyz[y, x]`` lies on the undistorted ray of left pixel ``(x, y)``.
    report : dict
        ``coverage`` (fraction of left pixels with a point), ``lr_rejected`` (fraction of SGBM
        matches the left-right check rejected), ``rectified_size`` ``(w, h)``,
        ``focal_rect_px``, ``baseline_mm``, ``minDisparity``, ``numDisparities``, ``wls``,
        and ``timings_s`` per stage (``rectify``, ``sgbm`` (both views), ``lr_check``,
        ``wls``, ``refine`` (texture check, refinement, edge trim), ``resample``, ``total``).

    Raises
    ------
    InputError
        Images not uint8 (H, W[, 3]), of different sizes, or of a size other than the
        calibration's; a vertical rig; bad ``params``; images that do not overlap (fewer
        left pixels reconstructed than ``min_coverage``).
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    p = stereo_params(params, source=str(source))
    grey_l = _grey(left, "left", source)
    grey_r = _grey(right, "right", source)
    if grey_l.shape != grey_r.shape:
        raise InputError(
            source,
            f"left/right: image sizes differ: left {grey_l.shape[1]}x{grey_l.shape[0]}, "
            f"right {grey_r.shape[1]}x{grey_r.shape[0]} (width x height)",
        )
    height, width = grey_l.shape
    validate_stereo_calibration(calib, source)
    if calib.image_size is not None and tuple(calib.image_size) != (width, height):
        raise InputError(
            source,
            f"calibration image_width/image_height {calib.image_size[0]}x{calib.image_size[1]} "
            f"differ from the images {width}x{height}",
        )

    t0 = time.perf_counter()
    rect = _rectify(calib, (width, height), p, source)
    margin = 0.5 * (int(p["blockSize"]) - 1)
    left_r, valid_l = _remap(grey_l, rect["maps1"], margin)
    right_r, valid_r = _remap(grey_r, rect["maps2"], margin)
    min_disp, num_disp = _disparity_range(rect, p)
    # SGBM leaves the first minDisparity + numDisparities columns of the left view without a
    # disparity (and the right matcher as many last columns of the right view): pad the canvas
    # so that no image content falls in those bands.
    pad_l, pad_r = _padding(valid_l, valid_r, min_disp, num_disp)
    left_r, right_r, valid_l, valid_r = (
        cv2.copyMakeBorder(a, 0, 0, pad_l, pad_r, cv2.BORDER_CONSTANT, value=0)
        for a in (left_r, right_r, valid_l.view(np.uint8), valid_r.view(np.uint8))
    )
    valid_l, valid_r = valid_l.astype(bool), valid_r.astype(bool)
    timings["rectify"] = time.perf_counter() - t0

    block = int(p["blockSize"])
    matcher = cv2.StereoSGBM_create(
        minDisparity=min_disp,
        numDisparities=num_disp,
        blockSize=block,
        P1=int(p["P1"] if p["P1"] is not None else 8 * block * block),
        P2=int(p["P2"] if p["P2"] is not None else 32 * block * block),
        disp12MaxDiff=-1,  # our own left-right check below
        preFilterCap=int(p["preFilterCap"]),
        uniquenessRatio=int(p["uniquenessRatio"]),
        speckleWindowSize=int(p["speckleWindowSize"]),
        speckleRange=int(p["speckleRange"]),
        mode=_MODES[p["mode"]],
    )
    t0 = time.perf_counter()
    disp_l16 = matcher.compute(left_r, right_r)
    right_matcher = cv2.ximgproc.createRightMatcher(matcher)
    disp_r16 = right_matcher.compute(right_r, left_r)
    timings["sgbm"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    matched_l = (disp_l16 >= 16 * min_disp) & valid_l
    matched_r = (disp_r16 >= 16 * right_matcher.getMinDisparity()) & valid_r
    consistent = _lr_consistent(disp_l16, disp_r16, matched_l, matched_r, p["lr_max_diff_px"])
    timings["lr_check"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if p["wls"]:
        wls = cv2.ximgproc.createDisparityWLSFilter(matcher)
        wls.setLambda(float(p["wls_lambda"]))
        wls.setSigmaColor(float(p["wls_sigma_color"]))
        disp16 = wls.filter(disp_l16, left_r, disparity_map_right=disp_r16)
    else:
        disp16 = disp_l16
    timings["wls"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    # WLS fills holes with guesses: keep only what the left-right check confirmed. SGM also
    # propagates disparities into untextured areas: keep only textured pixels.
    sigma = float(p["refine_sigma_px"])
    textured = _local_std(left_r, sigma, valid_l) >= float(p["min_texture"])
    disparity = np.where(consistent & textured, disp16.astype(np.float32) / 16.0, np.nan)
    if p["refine_iterations"] > 0:
        disparity = _refine_subpixel(
            left_r,
            right_r,
            disparity,
            int(p["refine_iterations"]),
            float(p["refine_sigma_px"]),
            float(p["min_zncc"]),
        )
    if p["edge_trim_px"] > 0:
        disparity = _trim_discontinuities(
            disparity, int(p["edge_trim_px"]), float(p["edge_jump_px"])
        )
    if p["erode_px"] > 0:
        disparity = _erode_valid(disparity, int(p["erode_px"]))
    disparity = disparity[:, pad_l : disparity.shape[1] - pad_r]
    timings["refine"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    xyz = _resample_left(disparity, rect, calib, (width, height), p["max_step_px"])
    timings["resample"] = time.perf_counter() - t0

    n_valid = int(np.count_nonzero(np.isfinite(xyz[..., 2])))
    coverage = n_valid / float(width * height)
    if n_valid == 0 or coverage < p["min_coverage"]:
        raise InputError(
            source,
            f"left/right: the images do not overlap as a stereo pair: {100 * coverage:.2f}% of "
            f"the left pixels were matched (floor {100 * p['min_coverage']:g}%); check that left "
            "and right belong to this calibration, are textured and see the same surface within "
            f"{p['min_depth_mm']:g}-{p['max_depth_mm']:g} mm",
        )
    timings["total"] = time.perf_counter() - t_start
    report = {
        "coverage": coverage,
        "lr_rejected": 1.0
        - int(np.count_nonzero(consistent)) / max(int(np.count_nonzero(matched_l)), 1),
        "rectified_size": rect["size"],
        "focal_rect_px": float(rect["P1"][0, 0]),
        "baseline_mm": calib.baseline_mm,
        "minDisparity": min_disp,
        "numDisparities": num_disp,
        "wls": bool(p["wls"]),
        "timings_s": timings,
    }
    return xyz, report


def _grey(image: np.ndarray, name: str, source: str | PathLike[str]) -> np.ndarray:
    """(H, W) uint8 grey version of an RGB or grey uint8 image."""
    image = np.asarray(image)
    if image.dtype != np.uint8 or not (
        image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)
    ):
        raise InputError(
            source,
            f"{name}: expected an (H, W, 3) or (H, W) uint8 image, got {image.shape} {image.dtype}",
        )
    if image.ndim == 2:
        return np.ascontiguousarray(image)
    return cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)


def _rectify(
    calib: StereoCalibration, size: tuple[int, int], p: Mapping[str, Any], source
) -> dict[str, Any]:
    """Rectification transforms and remap tables; the rectified focal length keeps the source's.

    With ``alpha = 1`` :func:`cv2.stereoRectify` shrinks the focal length so that every source
    pixel fits; the rectified image is enlarged instead (up to ``max_upscale``) so that the
    matching runs at the source resolution.
    """
    args = (calib.K1, calib.D1, calib.K2, calib.D2, size, calib.R, calib.T.reshape(3, 1))
    alpha = float(p["rectify_alpha"])
    new_size = size
    for _ in range(2):
        R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(
            *args, flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha, newImageSize=new_size
        )
        f_src = 0.5 * (calib.K1[0, 0] + calib.K1[1, 1])
        scale = min(f_src / P1[0, 0], float(p["max_upscale"]))
        if scale <= 1.0 + 1e-3 or new_size != size:
            break
        new_size = (int(np.ceil(size[0] * scale)), int(np.ceil(size[1] * scale)))
    if abs(P2[1, 3]) > abs(P2[0, 3]):
        raise InputError(
            source,
            "calibration T: the cameras are stacked vertically; "
            "only side-by-side rigs are supported",
        )
    maps1 = cv2.initUndistortRectifyMap(calib.K1, calib.D1, R1, P1, new_size, cv2.CV_32FC1)
    maps2 = cv2.initUndistortRectifyMap(calib.K2, calib.D2, R2, P2, new_size, cv2.CV_32FC1)
    return {
        "R1": R1,
        "R2": R2,
        "P1": P1,
        "P2": P2,
        "Q": Q,
        "size": new_size,
        "maps1": maps1,
        "maps2": maps2,
    }


def _remap(
    grey: np.ndarray, maps: tuple[np.ndarray, np.ndarray], margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rectified image and the mask of rectified pixels at least ``margin`` px inside the source.

    The margin keeps matching windows off the black surround of the rectified image.
    """
    out = cv2.remap(grey, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    h, w = grey.shape
    mx, my = maps
    inside = (mx >= margin) & (mx <= w - 1 - margin) & (my >= margin) & (my <= h - 1 - margin)
    return out, inside


def _disparity_range(rect: Mapping[str, Any], p: Mapping[str, Any]) -> tuple[int, int]:
    """SGBM's ``minDisparity`` and ``numDisparities`` covering the expected depth range.

    In the rectified pair ``d(Z) = (cx1 - cx2) - f Tx / Z`` with ``Tx = P2[0, 3] / f``.
    """
    P1, P2 = rect["P1"], rect["P2"]
    f = P1[0, 0]
    tx = P2[0, 3] / P2[0, 0]
    d = [(P1[0, 2] - P2[0, 2]) - f * tx / z for z in (p["min_depth_mm"], p["max_depth_mm"])]
    lo, hi = int(np.floor(min(d))) - 1, int(np.ceil(max(d))) + 1
    min_disp = int(p["minDisparity"]) if p["minDisparity"] is not None else lo
    if p["numDisparities"] is not None:
        num_disp = int(p["numDisparities"])
    else:
        num_disp = int(16 * np.ceil(max(hi - min_disp, 16) / 16))
    return min_disp, num_disp


def _padding(
    valid_l: np.ndarray, valid_r: np.ndarray, min_disp: int, num_disp: int
) -> tuple[int, int]:
    """Columns to add left and right so that SGBM's unmatched bands hold no image content.

    The left matcher leaves columns ``x < minDisparity + numDisparities`` (and, for a negative
    ``minDisparity``, the last ``-minDisparity``) empty; the right matcher mirrors that.
    """
    w = valid_l.shape[1]
    cols_l = np.flatnonzero(valid_l.any(axis=0))
    cols_r = np.flatnonzero(valid_r.any(axis=0))
    if cols_l.size == 0 or cols_r.size == 0:
        return 0, 0
    reach = min_disp + num_disp
    pad_l = max(0, reach - int(cols_l[0]), 1 - min_disp - int(cols_r[0]))
    pad_r = max(0, int(cols_r[-1]) + reach - w, int(cols_l[-1]) - min_disp + 1 - w)
    return pad_l, pad_r


def _lr_consistent(
    disp_l16: np.ndarray,
    disp_r16: np.ndarray,
    matched_l: np.ndarray,
    matched_r: np.ndarray,
    max_diff_px: float,
) -> np.ndarray:
    """Left pixels whose disparity the right view confirms.

    The right matcher reports the disparity of right pixel ``xr`` as ``-d`` for the match
    ``xl = xr + d``, so a consistent pair has ``d_left + d_right ~ 0``.

    Parameters
    ----------
    disp_l16, disp_r16 : (h, w) int16
        Left and right disparity maps, 1/16 px.
    matched_l, matched_r : (h, w) bool
        Pixels with a disparity, inside their source image.
    max_diff_px : float
        Largest accepted ``|d_left + d_right|``, px.
    """
    h, w = disp_l16.shape
    d_l = disp_l16.astype(np.float32) / 16.0
    xr = np.rint(np.arange(w, dtype=np.float32)[None, :] - d_l).astype(np.int64)
    inside = matched_l & (xr >= 0) & (xr < w)
    xr = np.clip(xr, 0, w - 1)
    rows = np.arange(h)[:, None]
    agree = np.abs(d_l + disp_r16[rows, xr].astype(np.float32) / 16.0) <= max_diff_px
    return inside & matched_r[rows, xr] & agree


def _local_std(image: np.ndarray, sigma: float, mask: np.ndarray | None = None) -> np.ndarray:
    """Standard deviation of the grey levels in a Gaussian window of ``sigma`` px, (h, w).

    With ``mask``, only the masked pixels count (so the black surround of a rectified image
    does not pass for texture).
    """
    img = image.astype(np.float32)
    if mask is None:
        mean = cv2.GaussianBlur(img, (0, 0), sigma)
        mean_sq = cv2.GaussianBlur(img * img, (0, 0), sigma)
    else:
        m = mask.astype(np.float32)
        norm = np.maximum(cv2.GaussianBlur(m, (0, 0), sigma), 1e-6)
        mean = cv2.GaussianBlur(img * m, (0, 0), sigma) / norm
        mean_sq = cv2.GaussianBlur(img * img * m, (0, 0), sigma) / norm
    return np.sqrt(np.maximum(mean_sq - mean * mean, 0.0))


def _normalised(image: np.ndarray, sigma: float) -> np.ndarray:
    """Image minus its local mean over its local standard deviation (Gaussian window).

    One grey level of variance is added so that flat areas stay near zero instead of
    amplifying noise.
    """
    img = image.astype(np.float32)
    mean = cv2.GaussianBlur(img, (0, 0), sigma)
    var = cv2.GaussianBlur(img * img, (0, 0), sigma) - mean * mean
    return (img - mean) / np.sqrt(np.maximum(var, 0.0) + 1.0)


def _refine_subpixel(
    left_r: np.ndarray,
    right_r: np.ndarray,
    disparity: np.ndarray,
    iterations: int,
    sigma: float,
    min_zncc: float,
) -> np.ndarray:
    """Sub-pixel refinement of a rectified disparity map by windowed Gauss-Newton.

    Minimises ``sum_q w(q - p) (L(q) - R(q - d(q)))^2`` over a correction of ``d(p)``, with
    ``w`` a Gaussian window and ``L``, ``R`` the locally normalised images (robust to gain and
    offset between the cameras); the gradient is the mean of both images' (ESM). This removes
    the pixel-locking bias of SGBM's parabola fit. Pixels that move by more than a pixel, or whose
    windowed ZNCC ends below ``min_zncc``, are dropped.

    Parameters
    ----------
    left_r, right_r : (h, w) uint8
        Rectified grey images.
    disparity : (h, w) float32
        Initial disparity, px; NaN where invalid.

    Returns
    -------
    (h, w) float32
        Refined disparity, px; NaN where invalid.
    """
    h, w = disparity.shape
    valid = np.isfinite(disparity)
    weight = valid.astype(np.float32)
    d0 = np.where(valid, disparity, 0.0).astype(np.float32)
    d = d0.copy()
    ln = _normalised(left_r, 2.0 * sigma)
    rn = _normalised(right_r, 2.0 * sigma)
    gl = cv2.Sobel(ln, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gr = cv2.Sobel(rn, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    xs = np.broadcast_to(np.arange(w, dtype=np.float32), (h, w))
    ys = np.ascontiguousarray(np.broadcast_to(np.arange(h, dtype=np.float32)[:, None], (h, w)))
    for _ in range(iterations):
        mx = np.ascontiguousarray(xs - d)
        rw = cv2.remap(rn, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        g = 0.5 * (gl + cv2.remap(gr, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE))
        e = ln - rw
        num = cv2.GaussianBlur(weight * g * e, (0, 0), sigma)
        den = cv2.GaussianBlur(weight * g * g, (0, 0), sigma)
        step = -num / np.maximum(den, 1e-6)
        d += weight * np.clip(step, -0.5, 0.5)
    keep = valid & (np.abs(d - d0) <= 1.0)
    if min_zncc > 0:
        mx = np.ascontiguousarray(xs - d)
        rw = cv2.remap(rn, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        sll = cv2.GaussianBlur(ln * ln, (0, 0), sigma)
        srr = cv2.GaussianBlur(rw * rw, (0, 0), sigma)
        slr = cv2.GaussianBlur(ln * rw, (0, 0), sigma)
        keep &= slr >= min_zncc * np.sqrt(sll * srr)
    return np.where(keep, d, np.nan).astype(np.float32)


def _trim_discontinuities(disparity: np.ndarray, radius: int, jump_px: float) -> np.ndarray:
    """Drop the band around depth discontinuities, where window matching adheres the wrong side.

    A pixel is dropped when the valid disparities within its (2 radius + 1)^2 window span more
    than ``jump_px`` (a continuous surface seen by both cameras changes its disparity by well
    under one px per px).
    """
    valid = np.isfinite(disparity)
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    big = np.float32(1e9)
    local_max = cv2.dilate(np.where(valid, disparity, -big).astype(np.float32), kernel)
    local_min = cv2.erode(np.where(valid, disparity, big).astype(np.float32), kernel)
    return np.where(valid & (local_max - local_min <= jump_px), disparity, np.nan).astype(
        np.float32
    )


def _erode_valid(disparity: np.ndarray, radius: int) -> np.ndarray:
    """Drop valid pixels within ``radius`` px of an invalid one."""
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    keep = cv2.erode(np.isfinite(disparity).astype(np.uint8), kernel).astype(bool)
    return np.where(keep, disparity, np.nan).astype(np.float32)


def _resample_left(
    disparity: np.ndarray,
    rect: Mapping[str, Any],
    calib: StereoCalibration,
    size: tuple[int, int],
    max_step_px: float,
) -> np.ndarray:
    """Points (H, W, 3) of the left image grid (unrectified left frame, mm) from the disparity.

    ``disparity`` is the (h, w) rectified left disparity, px, NaN where invalid.
    """
    width, height = size
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    pix = np.stack([xs.ravel(), ys.ravel()], axis=-1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-12)
    uv = cv2.undistortPoints(pix, calib.K1, calib.D1, R=rect["R1"], P=rect["P1"], criteria=criteria)
    u, v = uv[:, 0, 0], uv[:, 0, 1]

    hr, wr = disparity.shape
    u0 = np.floor(u).astype(np.int64)
    v0 = np.floor(v).astype(np.int64)
    inside = (u0 >= 0) & (u0 < wr - 1) & (v0 >= 0) & (v0 < hr - 1)
    u0c, v0c = np.where(inside, u0, 0), np.where(inside, v0, 0)
    corners = np.stack(
        [
            disparity[v0c, u0c],
            disparity[v0c, u0c + 1],
            disparity[v0c + 1, u0c],
            disparity[v0c + 1, u0c + 1],
        ]
    )
    spread = corners.max(axis=0) - corners.min(axis=0)  # NaN (so not ok) if any is invalid
    ok = inside & np.all(np.isfinite(corners), axis=0) & (spread <= max_step_px)
    fu, fv = u - u0, v - v0
    d = (
        corners[0] * (1 - fu) * (1 - fv)
        + corners[1] * fu * (1 - fv)
        + corners[2] * (1 - fu) * fv
        + corners[3] * fu * fv
    )
    d = np.where(ok, d, 1.0)
    Q = rect["Q"]
    w_ = Q[3, 0] * u + Q[3, 1] * v + Q[3, 2] * d + Q[3, 3]
    ok &= w_ * np.sign(Q[2, 3]) > 0  # in front of the camera
    # (u, v, d) -> rectified XYZ, as cv2.reprojectImageTo3D does per pixel; then R1^T maps the
    # rectified frame back to the left camera frame (cv2 transforms: numpy's tall-skinny
    # matmul is slow with a busy BLAS)
    uvd = np.stack([u, v, d], axis=-1).reshape(-1, 1, 3)
    xyz = cv2.transform(cv2.perspectiveTransform(uvd, Q), rect["R1"].T).reshape(-1, 3)
    xyz[~ok] = np.nan
    return xyz.reshape(height, width, 3)


__all__ = ["DEFAULT_STEREO", "reconstruct_stereo", "stereo_params"]
