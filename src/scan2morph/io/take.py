"""Loading one take's input files into arrays, with the cross-file checks."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
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
    h, w = xyz.shape[:2]
    outside = (
        (landmarks[:, 0] < -0.5)
        | (landmarks[:, 0] > w - 0.5)
        | (landmarks[:, 1] < -0.5)
        | (landmarks[:, 1] > h - 0.5)
    )
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise InputError(
            landmarks_path,
            f"point {k + 1} lies outside the {w}x{h} image ({int(outside.sum())} points outside)",
        )
    return RangeTake(xyz=xyz, color=color, landmarks=landmarks)
