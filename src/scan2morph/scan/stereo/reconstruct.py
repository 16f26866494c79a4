"""The stereo driver: a calibrated image pair to an organised range image.

:func:`reconstruct_stereo` runs the stages of :mod:`scan2morph.scan.stereo` (see there for
the algorithm) and reports coverage and timings.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from os import PathLike
from typing import Any

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.calibration import StereoCalibration
from scan2morph.scan.stereo.cleanup import (
    _erode_valid,
    _fill_small_holes,
    _remove_small_segments,
    _trim_discontinuities,
)
from scan2morph.scan.stereo.depth_range import _search_depths, _SearchDepths
from scan2morph.scan.stereo.params import stereo_params
from scan2morph.scan.stereo.resample import _resample_left
from scan2morph.scan.stereo.sgbm import (
    _lr_consistent,
    _match_views,
    _sgbm_matcher,
)
from scan2morph.scan.stereo.slanted import _grow, _PatchMatcher, _refine_patches, _validate
from scan2morph.scan.stereo.views import _grey_pair, _pad_pair, _RectifiedPair, _rectify_views
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
        ``focal_rect_px``, ``baseline_mm``, ``depth_range_mm`` ``[near, far]`` (the depth
        range searched, mm; ``far`` None when given disparities reach infinity),
        ``depth_range_source`` (``"derived"`` by the coarse pass of
        :mod:`~scan2morph.scan.stereo.depth_range`, or ``"config"``), ``coarse_scale``
        (its pyramid factor, 0 when not derived), ``minDisparity``, ``numDisparities``,
        ``wls``, ``grown_px`` (rectified pixels added by the growth, before validation),
        ``filled_px`` (rectified pixels of the small holes filled), and ``timings_s`` per
        stage (``rectify``, ``depth_range`` (the coarse pass), ``sgbm`` (both views),
        ``lr_check``, ``wls``, ``refine`` (texture check, windowed and per-pixel
        refinement), ``grow``, ``validate`` (window ZNCC and left-right check per pixel, edge
        trim, segments, hole filling), ``resample``, ``total``).

    Raises
    ------
    InputError
        Images not uint8 (H, W[, 3]), of different sizes, or of a size other than the
        calibration's; a vertical rig; bad ``params``; images that do not overlap (no depth
        range can be derived, or fewer left pixels reconstructed than ``min_coverage``).
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    p = stereo_params(params, source=str(source))
    grey_l, grey_r = _grey_pair(left, right, calib, source)
    size = (grey_l.shape[1], grey_l.shape[0])

    with _timed(timings, "rectify"):
        views = _rectify_views(grey_l, grey_r, calib, size, p, source)
    with _timed(timings, "depth_range"):
        depths = _search_depths(*views, p, source)
    with _timed(timings, "sgbm"):
        pair = _pad_pair(*views, depths, p)
        matcher = _sgbm_matcher(p, pair.min_disp, pair.num_disp)
        disp_l16, disp_r16, min_disp_r = _match_views(matcher, pair.left, pair.right)
    with _timed(timings, "lr_check"):
        matched_r, consistent, lr_rejected = _check_left_right(
            pair, disp_l16, disp_r16, min_disp_r, p
        )
    with _timed(timings, "wls"):
        disp16 = _smooth_wls(matcher, pair, disp_l16, disp_r16, p)
    with _timed(timings, "refine"):
        disparity, textured, patches = _refine(pair, disp16, consistent, p)
    with _timed(timings, "grow"):
        disparity, n_grown = _grow_into_neighbours(disparity, patches, textured & pair.valid_l, p)
    with _timed(timings, "validate"):
        disparity, n_filled = _clean(disparity, patches, pair, disp_r16, matched_r, p)
    with _timed(timings, "resample"):
        xyz = _resample_left(disparity, pair.rect, calib, size, p["max_step_px"])

    coverage = _coverage(xyz, p, depths, source)
    timings["total"] = time.perf_counter() - t_start
    report = _report(coverage, lr_rejected, n_grown, n_filled, pair, calib, p, timings)
    return xyz, report


# --------------------------------------------------------------------------------------------
# the steps, in the order of the driver


@contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    """Store the wall time (s) of the ``with`` block as ``timings[stage]``."""
    t0 = time.perf_counter()
    yield
    timings[stage] = time.perf_counter() - t0


def _check_left_right(
    pair: _RectifiedPair,
    disp_l16: np.ndarray,
    disp_r16: np.ndarray,
    min_disp_r: int,
    p: Mapping[str, Any],
) -> tuple[np.ndarray, np.ndarray, float]:
    """Left-right consistency check of the two SGBM disparities.

    Parameters
    ----------
    pair : _RectifiedPair
        The padded rectified views and their content masks, (Hr, Wp).
    disp_l16, disp_r16 : (Hr, Wp) int16
        SGBM disparities of the left and right view, 1/16 px.
    min_disp_r : int
        ``minDisparity`` of the right view's matcher, px.
    p : mapping
        Checked stereo parameters (``lr_max_diff_px``, px).

    Returns
    -------
    matched_r : (Hr, Wp) bool
        Right pixels with content and an SGBM match.
    consistent : (Hr, Wp) bool
        Left pixels whose match the right view confirms within ``lr_max_diff_px``.
    lr_rejected : float
        Fraction of the left view's matches the check rejected.
    """
    matched_l = (disp_l16 >= 16 * pair.min_disp) & pair.valid_l
    matched_r = (disp_r16 >= 16 * min_disp_r) & pair.valid_r
    consistent = _lr_consistent(disp_l16, disp_r16, matched_l, matched_r, p["lr_max_diff_px"])
    lr_rejected = 1.0 - int(np.count_nonzero(consistent)) / max(int(np.count_nonzero(matched_l)), 1)
    return matched_r, consistent, lr_rejected


def _smooth_wls(
    matcher: cv2.StereoSGBM,
    pair: _RectifiedPair,
    disp_l16: np.ndarray,
    disp_r16: np.ndarray,
    p: Mapping[str, Any],
) -> np.ndarray:
    """The left disparity, smoothed by opencv-contrib's WLS filter when ``p["wls"]``.

    Parameters
    ----------
    matcher : cv2.StereoSGBM
        The left view's matcher.
    pair : _RectifiedPair
        The padded rectified views (the left one guides the filter), (Hr, Wp) uint8.
    disp_l16, disp_r16 : (Hr, Wp) int16
        SGBM disparities of the left and right view, 1/16 px.
    p : mapping
        Checked stereo parameters (``wls``, ``wls_lambda``, ``wls_sigma_color``).

    Returns
    -------
    disp16 : (Hr, Wp) int16
        Left disparity, 1/16 px (``disp_l16`` itself without WLS).
    """
    if not p["wls"]:
        return disp_l16
    wls = cv2.ximgproc.createDisparityWLSFilter(matcher)
    wls.setLambda(float(p["wls_lambda"]))
    wls.setSigmaColor(float(p["wls_sigma_color"]))
    return wls.filter(disp_l16, pair.left, disparity_map_right=disp_r16)


def _refine(
    pair: _RectifiedPair, disp16: np.ndarray, consistent: np.ndarray, p: Mapping[str, Any]
) -> tuple[np.ndarray, np.ndarray, _PatchMatcher]:
    """Keep the confirmed textured matches; refine them to sub-pixel disparities.

    WLS fills holes with guesses and SGM propagates disparities into untextured areas: only
    the pixels the left-right check confirmed and that have local texture are kept. They are
    refined by windowed Gauss-Newton, then per pixel with the slanted window; small segments
    are dropped.

    Parameters
    ----------
    pair : _RectifiedPair
        The padded rectified views and their content masks, (Hr, Wp).
    disp16 : (Hr, Wp) int16
        Left disparity (after WLS, if on), 1/16 px.
    consistent : (Hr, Wp) bool
        Left pixels that passed the left-right check.
    p : mapping
        Checked stereo parameters (``refine_*``, ``min_texture``, ``patch_*``,
        ``min_segment_px``, ``segment_step_px``).

    Returns
    -------
    disparity : (Hr, Wp) float32
        Refined left disparity, px; NaN where there is none.
    textured : (Hr, Wp) bool
        Left pixels with local grey-level std of at least ``min_texture`` (window
        ``refine_sigma_px``).
    patches : _PatchMatcher
        The slanted-window matcher of the pair (used again by the growth and validation).
    """
    sigma = float(p["refine_sigma_px"])
    textured = _local_std(pair.left, sigma, pair.valid_l) >= float(p["min_texture"])
    disparity = np.where(consistent & textured, disp16.astype(np.float32) / 16.0, np.nan)
    if p["refine_iterations"] > 0:
        disparity = _refine_subpixel(
            pair.left,
            pair.right,
            disparity,
            int(p["refine_iterations"]),
            float(p["refine_sigma_px"]),
            float(p["min_zncc"]),
        )
    patches = _PatchMatcher(
        pair.left, pair.right, int(p["patch_radius_px"]), float(p["patch_sigma_px"])
    )
    if p["patch_iterations"] > 0:
        disparity = _refine_patches(
            disparity, patches, int(p["patch_iterations"]), sigma, bool(p["patch_curvature"])
        )
    min_segment, segment_step = int(p["min_segment_px"]), float(p["segment_step_px"])
    if min_segment > 0:
        disparity = _remove_small_segments(disparity, min_segment, segment_step)
    return disparity, textured, patches


def _grow_into_neighbours(
    disparity: np.ndarray, patches: _PatchMatcher, allowed: np.ndarray, p: Mapping[str, Any]
) -> tuple[np.ndarray, int]:
    """Grow the matched region into unmatched neighbours whose slanted window matches.

    Parameters
    ----------
    disparity : (Hr, Wp) float32
        Refined left disparity, px; NaN where there is none.
    patches : _PatchMatcher
        The slanted-window matcher of the pair.
    allowed : (Hr, Wp) bool
        Pixels the growth may add (textured, with content).
    p : mapping
        Checked stereo parameters (``grow_*``, ``patch_iterations``, ``refine_sigma_px``).

    Returns
    -------
    disparity : (Hr, Wp) float32
        Disparity with the grown pixels, px.
    n_grown : int
        Pixels added, px.
    """
    n_matched = int(np.count_nonzero(np.isfinite(disparity)))
    if p["grow_iterations"] > 0:
        disparity = _grow(
            disparity,
            patches,
            allowed,
            int(p["grow_iterations"]),
            float(p["grow_min_zncc"]),
            float(p["grow_max_change_px"]),
            int(p["patch_iterations"]),
            float(p["refine_sigma_px"]),
            bool(p["patch_curvature"]),
        )
    return disparity, int(np.count_nonzero(np.isfinite(disparity))) - n_matched


def _clean(
    disparity: np.ndarray,
    patches: _PatchMatcher,
    pair: _RectifiedPair,
    disp_r16: np.ndarray,
    matched_r: np.ndarray,
    p: Mapping[str, Any],
) -> tuple[np.ndarray, int]:
    """Validate every pixel, trim depth edges, drop segments, fill small holes, unpad.

    Parameters
    ----------
    disparity : (Hr, Wp) float32
        Left disparity after growth, px; NaN where there is none.
    patches : _PatchMatcher
        The slanted-window matcher of the pair.
    pair : _RectifiedPair
        The padded rectified views, their content masks and the padding.
    disp_r16 : (Hr, Wp) int16
        SGBM disparity of the right view, 1/16 px.
    matched_r : (Hr, Wp) bool
        Right pixels with content and an SGBM match.
    p : mapping
        Checked stereo parameters (``min_patch_zncc``, ``lr_max_diff_px``,
        ``pixel_texture_sigma_px``, ``edge_*``, ``erode_px``, ``min_segment_px``,
        ``segment_step_px``, ``fill_*``).

    Returns
    -------
    disparity : (Hr, Wr) float32
        Validated left disparity on the unpadded rectified canvas, px; NaN where there is none.
    n_filled : int
        Pixels of the small holes filled, px.
    """
    sigma = float(p["refine_sigma_px"])
    disp_r = np.where(matched_r, disp_r16.astype(np.float32) / 16.0, np.nan)
    pixel_textured = (
        _local_std(pair.left, float(p["pixel_texture_sigma_px"]), pair.valid_l) >= p["min_texture"]
    )
    disparity = _validate(
        disparity,
        patches,
        float(p["min_patch_zncc"]),
        disp_r,
        float(p["lr_max_diff_px"]),
        pixel_textured,
        sigma,
        bool(p["patch_curvature"]),
    )
    if p["edge_trim_px"] > 0:
        disparity = _trim_discontinuities(
            disparity, int(p["edge_trim_px"]), float(p["edge_jump_px"]), int(p["edge_gap_px"])
        )
    if p["erode_px"] > 0:
        disparity = _erode_valid(disparity, int(p["erode_px"]))
    min_segment, segment_step = int(p["min_segment_px"]), float(p["segment_step_px"])
    if min_segment > 0:
        disparity = _remove_small_segments(disparity, min_segment, segment_step)
    n_filled = 0
    if p["fill_max_px"] > 0:
        before = int(np.count_nonzero(np.isfinite(disparity)))
        disparity = _fill_small_holes(
            disparity, int(p["fill_max_px"]), float(p["fill_max_residual_px"]), pair.valid_l
        )
        n_filled = int(np.count_nonzero(np.isfinite(disparity))) - before
    return disparity[:, pair.pad_l : disparity.shape[1] - pair.pad_r], n_filled


def _coverage(
    xyz: np.ndarray, p: Mapping[str, Any], depths: _SearchDepths, source: str | PathLike[str]
) -> float:
    """Fraction of the left pixels with a point; an error below ``p["min_coverage"]``.

    Parameters
    ----------
    xyz : (H, W, 3) float64
        Points of the left pixels, mm; NaN where there is no data.
    p : mapping
        Checked stereo parameters (``min_coverage``).
    depths : _SearchDepths
        The depth range searched, mm (named in the message).
    source : str or path-like
        Label named in errors.

    Returns
    -------
    coverage : float
        Fraction of the H x W left pixels with a point.

    Raises
    ------
    InputError
        No point, or fewer than ``min_coverage``: the images do not overlap as a stereo pair.
    """
    n_valid = int(np.count_nonzero(np.isfinite(xyz[..., 2])))
    coverage = n_valid / float(xyz.shape[1] * xyz.shape[0])
    if n_valid == 0 or coverage < p["min_coverage"]:
        near, far = depths.depth_mm
        far_text = "infinity" if far is None else f"{far:.0f}"
        raise InputError(
            source,
            f"left/right: the images do not overlap as a stereo pair: {100 * coverage:.2f}% of "
            f"the left pixels were matched (floor {100 * p['min_coverage']:g}%); check that left "
            "and right belong to this calibration, are textured and see the same surface within "
            f"{near:.0f}-{far_text} mm (depth range {depths.source})",
        )
    return coverage


def _report(
    coverage: float,
    lr_rejected: float,
    n_grown: int,
    n_filled: int,
    pair: _RectifiedPair,
    calib: StereoCalibration,
    p: Mapping[str, Any],
    timings: dict[str, float],
) -> dict[str, Any]:
    """The report of :func:`reconstruct_stereo` (see there for its keys).

    Parameters
    ----------
    coverage : float
        Fraction of the left pixels with a point.
    lr_rejected : float
        Fraction of the left view's SGBM matches the left-right check rejected.
    n_grown, n_filled : int
        Rectified pixels added by the growth and by the hole filling, px.
    pair : _RectifiedPair
        The rectification (``size`` ``(Wr, Hr)`` px, focal length in px), the search range and
        its depths.
    calib : StereoCalibration
        The rig (baseline, mm).
    p : mapping
        Checked stereo parameters (``wls``).
    timings : dict
        Wall time per stage, s.

    Returns
    -------
    report : dict
        ``coverage``, ``lr_rejected``, ``rectified_size``, ``focal_rect_px``, ``baseline_mm``,
        ``depth_range_mm``, ``depth_range_source``, ``coarse_scale``, ``minDisparity``,
        ``numDisparities``, ``wls``, ``grown_px``, ``filled_px`` and ``timings_s``.
    """
    return {
        "coverage": coverage,
        "lr_rejected": lr_rejected,
        "rectified_size": pair.rect["size"],
        "focal_rect_px": float(pair.rect["P1"][0, 0]),
        "baseline_mm": calib.baseline_mm,
        "depth_range_mm": list(pair.depths.depth_mm),
        "depth_range_source": pair.depths.source,
        "coarse_scale": pair.depths.coarse_scale,
        "minDisparity": pair.min_disp,
        "numDisparities": pair.num_disp,
        "wls": bool(p["wls"]),
        "grown_px": n_grown,
        "filled_px": n_filled,
        "timings_s": timings,
    }


__all__ = ["reconstruct_stereo"]
