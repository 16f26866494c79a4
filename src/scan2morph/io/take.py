"""Loading one take's input files into arrays, with the cross-file checks."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.calibration import StereoCalibration, read_stereo_calibration
from scan2morph.io.image import read_color
from scan2morph.io.landmarks import read_pts
from scan2morph.io.range_image import read_range


@dataclass(frozen=True)
class RangeTake:
    """A range take: XYZ, color and landmarks on the same pixel grid.

    Attributes
    ----------
    xyz : (H, W, 3) float64
        mm, NaN = no data, in the take's scanner frame.
    color : (H, W, 3) uint8
        RGB, pixel to pixel with ``xyz``.
    landmarks : (68, 2) float64
        0-based pixel coordinates.
    """

    xyz: np.ndarray
    color: np.ndarray
    landmarks: np.ndarray


def read_range_take(
    xyz_path: str | Path, color_path: str | Path, landmarks_path: str | Path
) -> RangeTake:
    """Read a range take and check that its files agree.

    Raises
    ------
    InputError
        From the readers, or when the color image's size differs from the range image's, or when
        the range image holds no data at all.
    """
    xyz = read_range(xyz_path)
    color = read_color(color_path)
    if color.shape[:2] != xyz.shape[:2]:
        raise InputError(
            color_path,
            f"color: image is {color.shape[1]}x{color.shape[0]} (WxH) but the range image "
            f"{Path(xyz_path).name} is {xyz.shape[1]}x{xyz.shape[0]}; they must be pixel to pixel",
        )
    if not np.isfinite(xyz).any():
        raise InputError(xyz_path, "xyz: no valid pixel in the range image")
    landmarks = read_pts(landmarks_path)
    check_landmarks_inside(landmarks, xyz.shape[1], xyz.shape[0], landmarks_path)
    return RangeTake(xyz=xyz, color=color, landmarks=landmarks)


def check_landmarks_inside(
    landmarks: np.ndarray, width: int, height: int, source: str | Path
) -> None:
    """Check that landmarks lie on an image of ``width`` x ``height`` pixels.

    Parameters
    ----------
    landmarks : (n, 2) float
        0-based pixel coordinates ((0, 0) is the centre of the top-left pixel); a point may lie
        anywhere on a pixel, so the image spans ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
    width, height : int
        Image size, px.
    source : str or path-like
        The landmark file, named in the error.

    Raises
    ------
    InputError
        A point lies outside the image (names the first one, 1-based, and the count).
    """
    outside = (
        (landmarks[:, 0] < -0.5)
        | (landmarks[:, 0] > width - 0.5)
        | (landmarks[:, 1] < -0.5)
        | (landmarks[:, 1] > height - 0.5)
    )
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise InputError(
            source,
            f"point {k + 1} lies outside the {width}x{height} image "
            f"({int(outside.sum())} points outside)",
        )


@dataclass(frozen=True, eq=False)
class StereoTake:
    """A stereo take: the raw image pair, its calibration and the landmarks on the left image.

    Attributes
    ----------
    left, right : (H, W, 3) uint8
        RGB images of the left (first) and right (second) camera, raw (distorted).
    calib : StereoCalibration
        The rig, ``x_right = R x_left + T``, mm.
    landmarks : (68, 2) float64
        0-based pixel coordinates on the raw left image.
    """

    left: np.ndarray
    right: np.ndarray
    calib: StereoCalibration
    landmarks: np.ndarray


def read_stereo_take(
    left_path: str | Path,
    right_path: str | Path,
    calibration_path: str | Path,
    landmarks_path: str | Path,
) -> StereoTake:
    """Read a stereo take and check that its files agree.

    Parameters
    ----------
    left_path, right_path : str or path-like
        The raw images (PNG/PPM/JPEG) of the left (first) and right (second) camera.
    calibration_path : str or path-like
        OpenCV FileStorage YAML with ``K1 D1 K2 D2 R T`` (mm), see
        :func:`~scan2morph.io.read_stereo_calibration`.
    landmarks_path : str or path-like
        iBUG 68-point ``.pts`` on the raw left image.

    Returns
    -------
    StereoTake

    Raises
    ------
    InputError
        From the readers (a missing file, a calibration missing a matrix or with a wrong
        shape, a file that is not a calibration, a bad ``.pts``); the right image's size
        differs from the left's (names the right file); the calibration's
        ``image_width``/``image_height`` differ from the images' (names the calibration file);
        a landmark lies outside the left image (names the ``.pts`` file).
    """
    left = read_color(left_path)
    right = read_color(right_path)
    h, w = left.shape[:2]
    if right.shape[:2] != (h, w):
        raise InputError(
            right_path,
            f"right: image is {right.shape[1]}x{right.shape[0]} (WxH) but the left image "
            f"{Path(left_path).name} is {w}x{h}; the two images of a stereo pair must have "
            "the same size",
        )
    calib = read_stereo_calibration(calibration_path)
    if calib.image_size is not None and tuple(calib.image_size) != (w, h):
        raise InputError(
            calibration_path,
            f"image_width/image_height: {calib.image_size[0]}x{calib.image_size[1]} but the "
            f"images are {w}x{h} (WxH); is this the calibration of this camera pair?",
        )
    landmarks = read_pts(landmarks_path)
    check_landmarks_inside(landmarks, w, h, landmarks_path)
    return StereoTake(left=left, right=right, calib=calib, landmarks=landmarks)
