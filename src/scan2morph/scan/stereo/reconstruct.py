"""The stereo driver: a calibrated image pair to an organised range image.

:func:`reconstruct_stereo` runs the stages of :mod:`scan2morph.scan.stereo` (see there for
the algorithm) and reports coverage and timings.
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
from scan2morph.scan.stereo.cleanup import (
    _erode_valid,
    _fill_small_holes,
    _remove_small_segments,
    _trim_discontinuities,
)
from scan2morph.scan.stereo.params import stereo_params
from scan2morph.scan.stereo.rectify import _rectify, _remap
from scan2morph.scan.stereo.resample import _resample_left
from scan2morph.scan.stereo.sgbm import _disparity_range, _lr_consistent, _padding, _sgbm_matcher
from scan2morph.scan.stereo.slanted import _grow, _PatchMatcher, _refine_patches, _validate
from scan2morph.scan.stereo.windowed import _local_std, _refine_subpixel


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
        Overrides of :data:`~scan2morph.scan.stereo.DEFAULT_STEREO`.
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

    matcher = _sgbm_matcher(p, min_disp, num_disp)
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


__all__ = ["reconstruct_stereo"]
