"""The stereo pair prepared for matching: both images checked and made grey
(:func:`_grey_pair`), rectified (:func:`_rectify_views`) and padded onto SGBM's canvas with the
disparity range to search (:func:`_pad_pair`, :class:`_RectifiedPair`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from os import PathLike
from typing import Any

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.calibration import StereoCalibration, validate_stereo_calibration
from scan2morph.scan.stereo.depth_range import _SearchDepths
from scan2morph.scan.stereo.rectify import _rectify, _remap
from scan2morph.scan.stereo.sgbm import _disparity_range, _pad_views


def _grey_pair(
    left: np.ndarray, right: np.ndarray, calib: StereoCalibration, source: str | PathLike[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Check the pair against each other and the calibration; return both as grey.

    Parameters
    ----------
    left, right : (H, W, 3) uint8 or (H, W) uint8
        The raw images of the left and right camera.
    calib : StereoCalibration
        The rig; its ``image_size`` (px), if given, must be ``(W, H)``.
    source : str or path-like
        Label named in errors.

    Returns
    -------
    grey_l, grey_r : (H, W) uint8
        Grey versions of ``left`` and ``right``.

    Raises
    ------
    InputError
        Images not uint8 (H, W[, 3]), of different sizes or of a size other than the
        calibration's; a bad calibration.
    """
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
    return grey_l, grey_r


@dataclass(frozen=True)
class _RectifiedPair:
    """The rectified pair on SGBM's padded canvas (Hr rows, Wr + pad_l + pad_r columns).

    Attributes
    ----------
    rect : dict
        The rectification of :func:`~scan2morph.scan.stereo.rectify._rectify` (``P1``, ``R1``,
        ``size`` ``(Wr, Hr)`` px, remap tables, ...).
    left, right : (Hr, Wp) uint8
        Rectified grey views, 0 outside the images.
    valid_l, valid_r : (Hr, Wp) bool
        Pixels of the padded canvas holding image content (at least ``(blockSize - 1) / 2``
        px inside the source image).
    min_disp, num_disp : int
        SGBM's ``minDisparity`` and ``numDisparities``, px.
    pad_l, pad_r : int
        Columns added on the left and right of the rectified canvas, px.
    depths : _SearchDepths
        The depth range the search covers and where it came from.
    """

    rect: dict[str, Any]
    left: np.ndarray
    right: np.ndarray
    valid_l: np.ndarray
    valid_r: np.ndarray
    min_disp: int
    num_disp: int
    pad_l: int
    pad_r: int
    depths: _SearchDepths


def _rectify_views(
    grey_l: np.ndarray,
    grey_r: np.ndarray,
    calib: StereoCalibration,
    size: tuple[int, int],
    p: Mapping[str, Any],
    source: str | PathLike[str],
) -> tuple[dict[str, Any], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rectify both views.

    Parameters
    ----------
    grey_l, grey_r : (H, W) uint8
        Raw (distorted) grey views.
    calib : StereoCalibration
        The rig, mm.
    size : (int, int)
        ``(W, H)`` of the source images, px.
    p : mapping
        Checked stereo parameters (``blockSize`` px, rectification, ``rectify_interpolation``).
    source : str or path-like
        Label named in errors.

    Returns
    -------
    rect : dict
        The rectification (:func:`~scan2morph.scan.stereo.rectify._rectify`).
    left, right : (Hr, Wr) uint8
        Rectified grey views, 0 outside the images.
    valid_l, valid_r : (Hr, Wr) bool
        Rectified pixels at least ``(blockSize - 1) / 2`` px (and the interpolation's half
        support) inside the source image.
    """
    rect = _rectify(calib, size, p, source)
    margin = 0.5 * (int(p["blockSize"]) - 1)
    how = str(p["rectify_interpolation"])
    left_r, valid_l = _remap(grey_l, rect["maps1"], margin, how)
    right_r, valid_r = _remap(grey_r, rect["maps2"], margin, how)
    return rect, left_r, right_r, valid_l, valid_r


def _pad_pair(
    rect: dict[str, Any],
    left_r: np.ndarray,
    right_r: np.ndarray,
    valid_l: np.ndarray,
    valid_r: np.ndarray,
    depths: _SearchDepths,
    p: Mapping[str, Any],
) -> _RectifiedPair:
    """The search range of ``depths``; the canvas padded so SGBM's unmatched bands are empty.

    Parameters
    ----------
    rect : dict
        The rectification.
    left_r, right_r : (Hr, Wr) uint8
        Rectified grey views.
    valid_l, valid_r : (Hr, Wr) bool
        Their content masks.
    depths : _SearchDepths
        The depth range to search, mm.
    p : mapping
        Checked stereo parameters (``minDisparity``, ``numDisparities``).

    Returns
    -------
    _RectifiedPair
        Both views on the padded rectified canvas, their content masks and the search range.
    """
    near, far = depths.depth_mm
    range_p = {**p, "min_depth_mm": near, "max_depth_mm": far}
    min_disp, num_disp = _disparity_range(rect, range_p)
    # SGBM leaves the first minDisparity + numDisparities columns of the left view without a
    # disparity (and the right matcher as many last columns of the right view): pad the canvas
    # so that no image content falls in those bands.
    left_r, right_r, valid_l, valid_r, pad_l, pad_r = _pad_views(
        left_r, right_r, valid_l, valid_r, min_disp, num_disp
    )
    return _RectifiedPair(
        rect, left_r, right_r, valid_l, valid_r, min_disp, num_disp, pad_l, pad_r, depths
    )


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
