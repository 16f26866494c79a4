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
   images (removes the pixel-locking bias of SGBM's parabola fit), then **per pixel** with a
   small slanted window (the window follows the local disparity gradient, so slanted and
   foreshortened surfaces match too);
5. **growth**: unmatched pixels next to matched ones get the disparity extrapolated from their
   neighbours' planes, a short local search and the per-pixel refinement; they are kept when
   their slanted window matches (SGBM's fronto-parallel windows miss much of the steep skin
   next to occlusions, along the nose and the jaw);
6. **validation per pixel** instead of blanket bands: every pixel (grown ones included) must
   match with its slanted window (ZNCC) and agree with the right view (left-right check); at a
   depth discontinuity only the **background side** is trimmed, a narrow band where window
   matching sticks to the wrong surface (the occluded side of an occlusion gap along the
   epipolar line, and the pixels a foreground edge looks down on); small disconnected
   segments are dropped and small holes enclosed by a consistent plane are filled;
7. **resampling into the unrectified left image grid**: every left pixel is mapped to its
   rectified position (:func:`cv2.undistortPoints` with ``R=R1, P=P1``); it gets a point when
   the nearest rectified pixel is valid, with the disparity interpolated bilinearly over the
   four neighbours (a neighbour that is missing or more than ``max_step_px`` off the nearest
   one is completed from the plane of the other three, else replaced by the nearest one); the
   point ``Q @ (u, v, d, 1)`` (what :func:`cv2.reprojectImageTo3D` computes per pixel) is
   formed and rotated back from the rectified into the unrectified left camera frame
   (``R1^T``).

The result is the organised range image of a range scan, pixel to pixel with the left color
image: ``xyz[y, x]`` lies on the (undistorted) ray of left pixel ``(x, y)``.

Interpolating the disparity rather than the rectified XYZ is deliberate: disparity is an affine
function of the rectified pixel on a plane, so the interpolation is exact for planar patches and
the point stays exactly on the pixel's ray.

Measured on the 30 default synthetic stereo takes (3 subjects x 10 labels, config parameters)
over the face region: the per-pixel validation, the growth and the background-side trim (which
replaced a 4 px band around every depth edge and a 1 px erosion of every hole) give depth RMS
0.40 mm (0.26-0.49; before 0.45, 0.33-1.59) and coverage 0.88 (0.85-0.91; before 0.84,
0.80-0.87), median error 0.11 mm (0.15). The rest of the face is mostly hidden from the right
camera (1.4-2.3 %) or seen by it at a grazing angle (disparity gradient above 0.5 px/px,
2-4 %), where no window matches; the remaining errors sit within 3 px of occlusions and depth
steps.
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
    # per-pixel matching with a small slanted window (refinement, growth, validation)
    "patch_radius_px": 2,  # half side of the square window, px
    "patch_sigma_px": 1.5,  # Gaussian weight of the window, px
    "patch_iterations": 2,  # per-pixel Gauss-Newton steps; 0 keeps the windowed refinement's
    "grow_iterations": 4,  # rounds of growth into unmatched neighbours (1 px each); 0: off
    "grow_min_zncc": 0.5,  # least window ZNCC of a grown pixel (validation follows), -1..1
    "grow_max_change_px": 1.0,  # a grown pixel may leave its extrapolated disparity by this, px
    "min_patch_zncc": 0.875,  # validation: least window ZNCC of every pixel; -1: off
    "pixel_texture_sigma_px": 0.7,  # validation: min_texture also within this Gaussian, px
    # depth discontinuities: trim only their background (lower disparity) side
    "edge_trim_px": 2,  # width of the trimmed band, px
    "edge_jump_px": 2.0,  # a discontinuity: disparity step above this, px
    "edge_gap_px": 16,  # steps across up to this many unmatched pixels of a row count, px
    "erode_px": 0,  # drop valid pixels this close to an invalid one, px (superseded: 0)
    "min_segment_px": 100,  # drop connected disparity segments smaller than this, px; 0: off
    "segment_step_px": 1.0,  # largest disparity step between neighbours of one segment, px
    "fill_max_px": 50,  # fill enclosed holes up to this area from their border's plane, px
    "fill_max_residual_px": 0.5,  # ... when that border fits a plane within this, px
    "wls": False,  # WLS smoothing (measured on speckle: depth RMS 0.35 -> 0.45 mm, worse)
    "wls_lambda": 8000.0,
    "wls_sigma_color": 1.5,
    "max_step_px": 1.0,  # resampling: neighbours farther off the nearest one are completed, px
    # rectification
    "rectify_alpha": 1.0,  # cv2.stereoRectify's alpha: 1 keeps every source pixel
    "max_upscale": 1.5,  # the rectified image may grow by this factor to keep resolution
    # sanity
    "min_coverage": 0.05,  # fewest left pixels with a point, as a fraction of the image
}

#: Parameters that count pixels or steps (>= 0) and that are positive lengths or tolerances.
_COUNTS = (
    "patch_iterations",
    "grow_iterations",
    "edge_trim_px",
    "edge_gap_px",
    "erode_px",
    "min_segment_px",
    "fill_max_px",
)
_POSITIVE = (
    "patch_sigma_px",
    "pixel_texture_sigma_px",
    "grow_max_change_px",
    "edge_jump_px",
    "segment_step_px",
    "fill_max_residual_px",
)

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
    for key in _COUNTS:
        if p[key] < 0:
            raise InputError(source, f"{key}: expected >= 0, got {p[key]}")
    for key in _POSITIVE:
        if not p[key] > 0:
            raise InputError(source, f"{key}: expected > 0, got {p[key]}")
    if p["patch_radius_px"] < 1:
        raise InputError(source, f"patch_radius_px: expected >= 1, got {p['patch_radius_px']}")
    for key in ("grow_min_zncc", "min_patch_zncc"):
        if not -1 <= p[key] <= 1:
            raise InputError(source, f"{key}: expected a ZNCC in [-1, 1], got {p[key]}")
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
        ``grown_px`` (rectified pixels added by the growth, before validation), ``filled_px``
        (rectified pixels of the small holes filled), and ``timings_s`` per stage
        (``rectify``, ``sgbm`` (both views), ``lr_check``, ``wls``, ``refine`` (texture
        check, windowed and per-pixel refinement), ``grow``, ``validate`` (window ZNCC and
        left-right check per pixel, edge trim, segments, hole filling), ``resample``,
        ``total``).

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
    patches = _PatchMatcher(left_r, right_r, int(p["patch_radius_px"]), float(p["patch_sigma_px"]))
    if p["patch_iterations"] > 0:
        disparity = _refine_patches(disparity, patches, int(p["patch_iterations"]), sigma)
    min_segment, segment_step = int(p["min_segment_px"]), float(p["segment_step_px"])
    if min_segment > 0:
        disparity = _remove_small_segments(disparity, min_segment, segment_step)
    timings["refine"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    n_matched = int(np.count_nonzero(np.isfinite(disparity)))
    if p["grow_iterations"] > 0:
        disparity = _grow(
            disparity,
            patches,
            textured & valid_l,
            int(p["grow_iterations"]),
            float(p["grow_min_zncc"]),
            float(p["grow_max_change_px"]),
            int(p["patch_iterations"]),
            sigma,
        )
    n_grown = int(np.count_nonzero(np.isfinite(disparity))) - n_matched
    timings["grow"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    disp_r = np.where(matched_r, disp_r16.astype(np.float32) / 16.0, np.nan)
    pixel_textured = (
        _local_std(left_r, float(p["pixel_texture_sigma_px"]), valid_l) >= p["min_texture"]
    )
    disparity = _validate(
        disparity,
        patches,
        float(p["min_patch_zncc"]),
        disp_r,
        float(p["lr_max_diff_px"]),
        pixel_textured,
        sigma,
    )
    if p["edge_trim_px"] > 0:
        disparity = _trim_discontinuities(
            disparity, int(p["edge_trim_px"]), float(p["edge_jump_px"]), int(p["edge_gap_px"])
        )
    if p["erode_px"] > 0:
        disparity = _erode_valid(disparity, int(p["erode_px"]))
    if min_segment > 0:
        disparity = _remove_small_segments(disparity, min_segment, segment_step)
    n_filled = 0
    if p["fill_max_px"] > 0:
        before = int(np.count_nonzero(np.isfinite(disparity)))
        disparity = _fill_small_holes(
            disparity, int(p["fill_max_px"]), float(p["fill_max_residual_px"]), valid_l
        )
        n_filled = int(np.count_nonzero(np.isfinite(disparity))) - before
    disparity = disparity[:, pad_l : disparity.shape[1] - pad_r]
    timings["validate"] = time.perf_counter() - t0

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
        "grown_px": n_grown,
        "filled_px": n_filled,
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


#: Most rows of one :func:`cv2.remap` table (OpenCV takes fewer than 32767).
_REMAP_ROWS = 32000


def _sample(
    image: np.ndarray, map_x: np.ndarray, map_y: np.ndarray, interpolation: int = cv2.INTER_CUBIC
) -> np.ndarray:
    """Sample an image at arbitrary positions (:func:`cv2.remap` in blocks of rows).

    Parameters
    ----------
    image : (h, w) float32
    map_x, map_y : (n, k) float32
        Positions, px ((0, 0) = centre of the top-left pixel).
    interpolation : int
        OpenCV interpolation flag.

    Returns
    -------
    (n, k) float32
        The image there (replicated beyond its border).
    """
    out = np.empty(map_x.shape, np.float32)
    for start in range(0, map_x.shape[0], _REMAP_ROWS):
        rows = slice(start, start + _REMAP_ROWS)
        out[rows] = cv2.remap(
            image, map_x[rows], map_y[rows], interpolation, borderMode=cv2.BORDER_REPLICATE
        )
    return out


def _standardise(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Standardise windows in place: minus their weighted mean, over their weighted std.

    Parameters
    ----------
    values : (n, k) float32
        One window per row; overwritten.
    weights : (k,) float32
        Window weights, summing to 1.

    Returns
    -------
    (n,) float32
        1 / std of every window (before standardising).
    """
    values -= (values @ weights)[:, None]
    inv_std = 1.0 / np.sqrt(np.einsum("ij,ij,j->i", values, values, weights, optimize=True) + 1e-6)
    values *= inv_std[:, None]
    return inv_std


class _PatchMatcher:
    """Match single rectified left pixels in the right image with a small slanted window.

    The window of left pixel ``(x, y)`` holds the pixels ``(x + ox, y + oy)``,
    ``|ox|, |oy| <= radius``, Gaussian weighted (``sigma``); they match the right image at
    ``(x + ox - (d + a ox + b oy), y + oy)``: the window follows the plane of disparity ``d``
    and gradient ``(a, b)`` (px per px), so slanted and foreshortened surfaces match as well as
    fronto-parallel ones, and the result belongs to the pixel (a window of a few pixels). The
    windows are compared after removing their mean and gain (ZNCC).

    Parameters
    ----------
    left_r, right_r : (h, w) uint8
        Rectified grey images.
    radius : int
        Half side of the window, px.
    sigma : float
        Gaussian weight of the window, px.
    """

    def __init__(self, left_r: np.ndarray, right_r: np.ndarray, radius: int, sigma: float):
        h, w = left_r.shape
        left = left_r.astype(np.float32)
        self.right = right_r.astype(np.float32)
        self.right_dx = cv2.Sobel(self.right, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        o = np.arange(-radius, radius + 1)
        oy, ox = (t.ravel() for t in np.meshgrid(o, o, indexing="ij"))
        self.steps = o.astype(np.float32)
        self.ox, self.oy = ox.astype(np.float32), oy.astype(np.float32)
        # the left image and its x-gradient, flattened with a margin so that every window of
        # a canvas pixel can be gathered with flat offsets (windows cut by the left or right
        # border wrap to the neighbouring row)
        self.width, self.margin = w, radius * (w + 1)
        self.offsets = oy * w + ox + self.margin
        dx = cv2.Sobel(left, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        self.left_flat, self.left_dx_flat = (np.pad(a.ravel(), self.margin) for a in (left, dx))
        weights = np.exp(-(ox * ox + oy * oy) / (2.0 * sigma * sigma)).astype(np.float32)
        self.weights = weights / weights.sum()

    def left_windows(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Standardised left windows of canvas pixels and their x-gradients.

        Parameters
        ----------
        ys, xs : (n,) int
            Pixels of the rectified canvas.

        Returns
        -------
        values, dx : (n, k) float32
            The standardised windows and the image x-gradient there, divided by the same std.
        """
        flat = (ys * self.width + xs)[:, None] + self.offsets[None]
        values = self.left_flat[flat]
        inv_std = _standardise(values, self.weights)
        dx = self.left_dx_flat[flat]
        dx *= inv_std[:, None]
        return values, dx

    def _window_columns(self, xs, d, a, b) -> np.ndarray:
        """Right-image x of the windows, (n, k) float32 (their rows are ``ys + oy``)."""
        # x + ox - (d + a ox + b oy) = (x - d - b oy) + (1 - a) ox, over the window's rows
        # (oy, outer index) and columns (ox, inner index)
        per_row = np.multiply.outer(-b.astype(np.float32), self.steps)
        per_row += (xs - d).astype(np.float32)[:, None]
        per_col = np.multiply.outer((1.0 - a).astype(np.float32), self.steps)
        return (per_row[:, :, None] + per_col[:, None, :]).reshape(len(xs), -1)

    def window_rows(self, ys) -> np.ndarray:
        """Image rows of the windows, (n, k) float32."""
        return np.add.outer(ys.astype(np.float32), self.oy)

    def zncc(self, left, ys, xs, d, a, b, maps_y=None) -> np.ndarray:
        """Window ZNCC of left pixels at their disparity planes.

        Parameters
        ----------
        left : tuple of (n, k) float32
            The pixels' :meth:`left_windows`.
        ys, xs : (n,) int
            The pixels.
        d : (n,) float32
            Disparity at the pixel, px.
        a, b : (n,) float32
            Disparity gradient along x and y, px per px.
        maps_y : (n, k) float32, optional
            The pixels' :meth:`window_rows` (computed when not given).

        Returns
        -------
        (n,) float32
            ZNCC in [-1, 1].
        """
        maps_y = self.window_rows(ys) if maps_y is None else maps_y
        right = _sample(self.right, self._window_columns(xs, d, a, b), maps_y)
        _standardise(right, self.weights)
        return np.einsum("ij,ij,j->i", left[0], right, self.weights, optimize=True)

    def refine(
        self, left, ys, xs, d, a, b, iterations: int, score: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Gauss-Newton refinement of the disparity of left pixels with their own windows.

        Minimises the weighted squared difference of the standardised windows over ``d`` (the
        gradient ``(a, b)`` is kept), with the mean gradient of both images (ESM); steps are
        clipped to half a pixel.

        Parameters
        ----------
        left, ys, xs, d, a, b
            As in :meth:`zncc`; ``d`` is the starting disparity, px.
        iterations : int
            Gauss-Newton steps.
        score : bool
            Also return the ZNCC at the result.

        Returns
        -------
        d : (n,) float32
            Refined disparity, px.
        zncc : (n,) float32 or None
            Window ZNCC at ``d`` (None unless ``score``).
        """
        left_values, left_dx = left
        maps_y = self.window_rows(ys)
        d = d.astype(np.float32).copy()
        for _ in range(iterations):
            maps_x = self._window_columns(xs, d, a, b)
            err = _sample(self.right, maps_x, maps_y)
            grad = _sample(self.right_dx, maps_x, maps_y, cv2.INTER_LINEAR)
            grad *= _standardise(err, self.weights)[:, None]
            grad += left_dx  # twice the mean gradient; d(left - right(x - d)) / dd = right_x
            np.subtract(left_values, err, out=err)
            num = np.einsum("ij,ij,j->i", grad, err, self.weights, optimize=True)
            den = np.einsum("ij,ij,j->i", grad, grad, self.weights, optimize=True)
            d += np.clip(-2.0 * num / np.maximum(den, 1e-6), -0.5, 0.5)
        return d, (self.zncc(left, ys, xs, d, a, b, maps_y) if score else None)


def _disparity_slopes(disparity: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Gradient of the disparity field, defined next to holes too.

    Central differences of the field smoothed by normalised convolution (a Gaussian over the
    valid pixels only).

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    sigma : float
        The Gaussian, px.

    Returns
    -------
    gx, gy : (h, w) float32
        d(disparity)/dx and d(disparity)/dy, px per px.
    """
    valid = np.isfinite(disparity)
    weight = cv2.GaussianBlur(valid.astype(np.float32), (0, 0), sigma)
    smooth = cv2.GaussianBlur(np.where(valid, disparity, 0.0).astype(np.float32), (0, 0), sigma)
    smooth /= np.maximum(weight, 1e-6)
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=1, scale=0.5)
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=1, scale=0.5)
    return gx, gy


def _refine_patches(
    disparity: np.ndarray, matcher: _PatchMatcher, iterations: int, slope_sigma: float
) -> np.ndarray:
    """Refine every valid disparity with its own slanted window; drop those that move > 1 px.

    The windowed refinement (:func:`_refine_subpixel`) averages the steps of a neighbourhood;
    this one fits each pixel's own small window (``patch_radius_px``), which sharpens the
    disparity at curved and slanted skin (measured: median depth error 0.15 -> 0.11 mm).

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    matcher : _PatchMatcher
        The rectified pair's slanted-window matcher.
    iterations : int
        Gauss-Newton steps.
    slope_sigma : float
        Smoothing of the disparity gradient that slants the windows, px.

    Returns
    -------
    (h, w) float32
    """
    ys, xs = np.nonzero(np.isfinite(disparity))
    if ys.size == 0:
        return disparity
    gx, gy = _disparity_slopes(disparity, slope_sigma)
    d0 = disparity[ys, xs]
    left = matcher.left_windows(ys, xs)
    d, _ = matcher.refine(left, ys, xs, d0, gx[ys, xs], gy[ys, xs], iterations, score=False)
    out = np.full_like(disparity, np.nan)
    out[ys, xs] = np.where(np.abs(d - d0) <= 1.0, d, np.nan)
    return out


def _extrapolate(
    disparity: np.ndarray, gx: np.ndarray, gy: np.ndarray, ys: np.ndarray, xs: np.ndarray
) -> np.ndarray:
    """Disparity of pixels predicted by the planes of their valid 8-neighbours.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    gx, gy : (h, w) float32
        Its gradient along x and y, px per px (:func:`_disparity_slopes`).
    ys, xs : (n,) int
        The pixels.

    Returns
    -------
    (n,) float32
        The mean of ``d(q) + g(q) . (p - q)`` over the valid neighbours ``q`` of each pixel
        ``p``, px; NaN where there is none.
    """
    h, w = disparity.shape
    total = np.zeros(ys.size, np.float32)
    count = np.zeros(ys.size, np.int32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == 0 and dx == 0:
                continue
            qy, qx = np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)
            pred = disparity[qy, qx] - gx[qy, qx] * dx - gy[qy, qx] * dy
            ok = np.isfinite(pred)
            total += np.where(ok, pred, 0.0)
            count += ok
    return np.where(count > 0, total / np.maximum(count, 1), np.nan).astype(np.float32)


#: Offsets of the growth's local search around the extrapolated disparity, px.
_GROW_SEARCH_PX = (-1.0, -0.5, 0.0, 0.5, 1.0)


def _grow(
    disparity: np.ndarray,
    matcher: _PatchMatcher,
    allowed: np.ndarray,
    rounds: int,
    min_zncc: float,
    max_change_px: float,
    iterations: int,
    slope_sigma: float,
) -> np.ndarray:
    """Extend the valid disparity into unmatched neighbours, verified by their own windows.

    Each round, every unmatched ``allowed`` pixel with at least two valid 8-neighbours gets
    the disparity its neighbours' planes predict (:func:`_extrapolate`), the best of a local
    search within +-1 px (window ZNCC) and ``iterations`` Gauss-Newton steps of its slanted
    window; it is kept when its ZNCC reaches ``min_zncc`` and it stayed within
    ``max_change_px`` of the prediction. SGBM's fronto-parallel blocks miss much of the steep
    skin (foreshortened in one view) next to occlusions; the slanted window recovers it. The
    strict validation (:func:`_validate`) follows.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    matcher : _PatchMatcher
        The rectified pair's slanted-window matcher.
    allowed : (h, w) bool
        Pixels that may be grown (textured, inside the left image).
    rounds : int
        Growth rounds (each reaches 1 px farther).
    min_zncc : float
        Least window ZNCC of a grown pixel.
    max_change_px : float
        Largest departure of a grown pixel from its predicted disparity, px.
    iterations : int
        Gauss-Newton steps per grown pixel.
    slope_sigma : float
        Smoothing of the disparity gradient, px.

    Returns
    -------
    (h, w) float32
    """
    d = disparity.copy()
    for _ in range(rounds):
        valid = np.isfinite(d)
        neighbours = cv2.filter2D(
            valid.astype(np.uint8), -1, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT
        )
        ys, xs = np.nonzero(~valid & allowed & (neighbours >= 2))
        if ys.size == 0:
            break
        gx, gy = _disparity_slopes(d, slope_sigma)
        d0, a, b = _extrapolate(d, gx, gy, ys, xs), gx[ys, xs], gy[ys, xs]
        left, maps_y = matcher.left_windows(ys, xs), matcher.window_rows(ys)
        best_z = np.full(ys.size, -np.inf, np.float32)
        best_d = d0.copy()
        for offset in _GROW_SEARCH_PX:
            z = matcher.zncc(left, ys, xs, d0 + offset, a, b, maps_y)
            better = z > best_z
            best_z = np.where(better, z, best_z)
            best_d = np.where(better, d0 + offset, best_d)
        grown, z = matcher.refine(left, ys, xs, best_d, a, b, iterations)
        keep = (z >= min_zncc) & (np.abs(grown - d0) <= max_change_px)
        if not keep.any():
            break
        d[ys[keep], xs[keep]] = grown[keep]
    return d


def _validate(
    disparity: np.ndarray,
    matcher: _PatchMatcher,
    min_zncc: float,
    disp_right: np.ndarray,
    lr_max_diff_px: float,
    textured: np.ndarray,
    slope_sigma: float,
) -> np.ndarray:
    """Keep the pixels whose own slanted window matches and that the right view confirms.

    Replaces the erosion of every hole border: a pixel is dropped for its own evidence only,
    when its window ZNCC (:class:`_PatchMatcher`) is below ``min_zncc`` (-1: no check), when
    the right view's SGBM disparity at its match disagrees by more than ``lr_max_diff_px``
    (the left-right check again, now for refined and grown pixels; where the right view has no
    disparity the window decides alone), or when it is not ``textured`` itself (an untextured
    background pixel next to a silhouette matches the silhouette's edge).

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified left disparity, px; NaN where invalid.
    matcher : _PatchMatcher
        The rectified pair's slanted-window matcher.
    min_zncc : float
        Least window ZNCC.
    disp_right : (h, w) float32
        The right view's disparity (``-d`` for the match ``xl = xr + d``), px; NaN where none.
    lr_max_diff_px : float
        Largest accepted ``|d_left + d_right|``, px.
    textured : (h, w) bool
        Pixels with texture of their own (the grey-level std within a small window).
    slope_sigma : float
        Smoothing of the disparity gradient, px.

    Returns
    -------
    (h, w) float32
    """
    ys, xs = np.nonzero(np.isfinite(disparity) & textured)
    out = np.full_like(disparity, np.nan)
    if ys.size == 0:
        return out
    d = disparity[ys, xs]
    keep = np.ones(ys.size, bool)
    if min_zncc > -1.0:
        gx, gy = _disparity_slopes(disparity, slope_sigma)
        left = matcher.left_windows(ys, xs)
        keep &= matcher.zncc(left, ys, xs, d, gx[ys, xs], gy[ys, xs]) >= min_zncc
    xr = np.clip(np.rint(xs - d).astype(np.int64), 0, disparity.shape[1] - 1)
    keep &= ~(np.abs(d + disp_right[ys, xr]) > lr_max_diff_px)  # NaN (no match) passes
    out[ys[keep], xs[keep]] = d[keep]
    return out


def _remove_small_segments(disparity: np.ndarray, min_px: int, step_px: float) -> np.ndarray:
    """Drop connected segments of fewer than ``min_px`` pixels (:func:`cv2.filterSpeckles`).

    Neighbours belong to one segment when their disparities differ by at most ``step_px``:
    islands of wrong matches (e.g. in an occluded band) differ from the surface around them.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    min_px : int
        Smallest segment kept, px.
    step_px : float
        Largest disparity step inside a segment, px.

    Returns
    -------
    (h, w) float32
    """
    valid = np.isfinite(disparity)
    invalid = -32768
    fixed = np.clip(np.rint(np.where(valid, disparity, 0.0) * 16.0), -32767, 32767)
    d16 = np.where(valid, fixed, invalid).astype(np.int16)
    cv2.filterSpeckles(d16, invalid, int(min_px), int(round(16.0 * step_px)))
    return np.where(d16 != invalid, disparity, np.nan).astype(np.float32)


def _fill_small_holes(
    disparity: np.ndarray, max_px: int, max_residual_px: float, allowed: np.ndarray
) -> np.ndarray:
    """Fill small holes enclosed by one consistent surface with its plane.

    A hole (4-connected unmatched pixels) of at most ``max_px`` pixels, inside ``allowed`` and
    not touching the canvas border, is filled when the disparities of its border ring (its
    8-neighbours) fit a plane in ``(x, y)`` within ``max_residual_px``; the hole gets that
    plane. Holes at depth discontinuities (a ring on two surfaces) and large holes stay.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    max_px : int
        Largest hole filled, px (area).
    max_residual_px : float
        Largest deviation of a ring pixel from the fitted plane, px.
    allowed : (h, w) bool
        Pixels that may be filled (inside the left image).

    Returns
    -------
    (h, w) float32
    """
    holes = (~np.isfinite(disparity)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(holes, connectivity=4)
    h, w = disparity.shape
    out = disparity.copy()
    ring_kernel = np.ones((3, 3), np.uint8)
    for i in np.flatnonzero(stats[:, cv2.CC_STAT_AREA] <= max_px):
        x0, y0, bw, bh = stats[i, :4]
        if i == 0 or x0 == 0 or y0 == 0 or x0 + bw >= w or y0 + bh >= h:
            continue
        box = (slice(y0 - 1, y0 + bh + 1), slice(x0 - 1, x0 + bw + 1))
        hole = labels[box] == i
        ring = cv2.dilate(hole.astype(np.uint8), ring_kernel).astype(bool) & ~hole
        ry, rx = np.nonzero(ring)
        d = disparity[box][ry, rx].astype(np.float64)
        hy, hx = np.nonzero(hole)
        if not (np.all(np.isfinite(d)) and allowed[box][hy, hx].all()):
            continue
        design = np.stack([np.ones(rx.size), rx, ry], axis=1).astype(np.float64)
        coef = np.linalg.lstsq(design, d, rcond=None)[0]
        if np.abs(d - design @ coef).max() > max_residual_px:
            continue
        out[box][hy, hx] = coef[0] + coef[1] * hx + coef[2] * hy
    return out


def _trim_discontinuities(
    disparity: np.ndarray, width: int, jump_px: float, gap_px: int
) -> np.ndarray:
    """Drop the background side of depth discontinuities, where window matching errs.

    A window that straddles a step matches the texture of the side that fills most of it, so
    the errors of the matched disparities sit on the low-disparity (background) side: the
    foreground's disparity, or garbage matched in the band the foreground hides from the right
    camera (the occluded side of an occlusion). The foreground side is kept. Two rules:

    * a pixel is dropped when a valid pixel within ``width`` px (Chebyshev) has a disparity
      more than ``jump_px`` above its own (steps in any direction, e.g. below the nose);
    * along each row (the epipolar line), where two valid pixels are separated by 1 to
      ``gap_px`` unmatched ones (an occlusion gap, or the silhouette against an untextured
      background) and their disparities differ by more than ``jump_px``, the ``width`` pixels
      of the lower side next to the gap are dropped.

    A continuous surface changes its disparity by well under ``jump_px`` per px except where
    it is seen at a grazing angle.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    width : int
        Width of the trimmed band, px (>= 1).
    jump_px : float
        Disparity step that makes a discontinuity, px.
    gap_px : int
        Longest run of unmatched pixels across which a row step still counts, px.

    Returns
    -------
    (h, w) float32
    """
    valid = np.isfinite(disparity)
    kernel = np.ones((2 * width + 1, 2 * width + 1), np.uint8)
    filled = np.where(valid, disparity, np.float32(-1e9)).astype(np.float32)
    drop = cv2.dilate(filled, kernel) - filled > jump_px
    if gap_px > 0:
        h, w = disparity.shape
        cols = np.broadcast_to(np.arange(w), (h, w))
        beyond = w + gap_px + 1
        # the next valid pixel strictly to the right of every pixel (beyond: none)
        nearest = np.minimum.accumulate(np.where(valid, cols, beyond)[:, ::-1], axis=1)[:, ::-1]
        nxt = np.concatenate([nearest[:, 1:], np.full((h, 1), beyond)], axis=1)
        gap = nxt - cols - 1
        pair = valid & (nxt < w) & (gap >= 1) & (gap <= gap_px)
        rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
        step = np.where(pair, disparity[rows, np.minimum(nxt, w - 1)] - disparity, 0.0)
        low_left = (step > jump_px).astype(np.uint8)  # this pixel is the low side
        low_right = np.zeros((h, w), np.uint8)  # the next valid pixel is the low side
        ry, rx = np.nonzero(step < -jump_px)
        low_right[ry, nxt[ry, rx]] = 1
        band = np.ones((1, width), np.uint8)
        # extend the seeds away from the gap: to the left, respectively to the right
        drop |= cv2.dilate(low_left, band, anchor=(0, 0)).astype(bool)
        drop |= cv2.dilate(low_right, band, anchor=(width - 1, 0)).astype(bool)
    return np.where(valid & ~drop, disparity, np.nan).astype(np.float32)


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

    Every left pixel maps to a rectified position ``(u, v)``; it gets a point when the
    rectified pixel nearest to ``(u, v)`` is valid, so the valid region keeps its extent (no
    half-pixel erosion at its borders). The disparity there is the bilinear interpolation of
    the four rectified neighbours; a neighbour that is invalid or differs from the nearest one
    by more than ``max_step_px`` (across a discontinuity) is completed from the plane of the
    other three (``d00 + d11 = d01 + d10``) when they are valid and close, else replaced by the
    nearest one. Bilinear interpolation of the disparity is exact on planes.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified left disparity, px; NaN where invalid.
    rect : mapping
        :func:`_rectify`'s transforms.
    calib : StereoCalibration
    size : (W, H)
        Left image size, px.
    max_step_px : float
        Largest difference from the nearest neighbour of a neighbour interpolated as is, px.

    Returns
    -------
    (H, W, 3) float64
        NaN where there is no point.
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
    # corners 0 (v0, u0), 1 (v0, u0 + 1), 2 (v0 + 1, u0), 3 (v0 + 1, u0 + 1)
    corners = np.stack(
        [
            disparity[v0c, u0c],
            disparity[v0c, u0c + 1],
            disparity[v0c + 1, u0c],
            disparity[v0c + 1, u0c + 1],
        ]
    )
    fu, fv = u - u0, v - v0
    nearest = (fu >= 0.5).astype(np.int64) + 2 * (fv >= 0.5).astype(np.int64)
    d_near = np.take_along_axis(corners, nearest[None], axis=0)[0]
    usable = np.abs(corners - d_near) <= max_step_px  # False where NaN
    completed = corners.copy()
    for i, (j, k, opposite) in enumerate(((1, 2, 3), (0, 3, 2), (0, 3, 1), (1, 2, 0))):
        plane = usable[j] & usable[k] & usable[opposite]
        fill = np.where(plane, corners[j] + corners[k] - corners[opposite], d_near)
        completed[i] = np.where(usable[i], corners[i], fill)
    ok = inside & np.isfinite(d_near)
    d = (
        completed[0] * (1 - fu) * (1 - fv)
        + completed[1] * fu * (1 - fv)
        + completed[2] * (1 - fu) * fv
        + completed[3] * fu * fv
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
