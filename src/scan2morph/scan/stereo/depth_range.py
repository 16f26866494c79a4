"""The depth range of the disparity search: from the configuration, or derived from the pair.

Without a configured range (``min_depth_mm`` and ``max_depth_mm`` null, the default) a coarse
pass measures it, so that a rig at any working distance works without tuning:

1. the **widest plausible search**: depths from 0.2 to 5 m (``_WIDE_DEPTH_MM``), clipped to
   the disparities that fit the rectified images (a left and a right column with content);
2. a **Gaussian pyramid** of the rectified pair (:func:`cv2.pyrDown`, factor ``s = 2^k``, the
   smallest that brings that search to at most ``_COARSE_DISPARITIES`` px and the view to at
   most ``_COARSE_WIDTH`` px), so the wide search is cheap (a few hundredths of a second);
3. **semi-global matching** of both coarse views over the wide search, the **left-right
   check** and the **texture check** (flat background has no texture);
4. the matches are split into **segments** (4-connected, no disparity step above
   ``_SEGMENT_STEP_PX`` coarse px); segments smaller than ``_MIN_SEGMENT_FRACTION`` of the
   coarse left view or than ``_RELATIVE_SEGMENT`` of the largest one are ignored (mismatches,
   specks), the others (the face, and a textured background if there is one) give their
   robust disparity extent (percentiles ``_PERCENTILES``);
5. that extent, widened by ``s`` px of disparity (the coarse pass's resolution), converted
   to depth and widened by ``depth_margin_mm`` on both sides (what the coarse pass misses of a
   face: the nose tip, steep sides, ears), is the depth range of the fine pass.

An explicit range in the parameters wins; so do explicit ``minDisparity`` and
``numDisparities`` (the depth range then only describes them).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from os import PathLike
from typing import Any

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.scan.stereo.cleanup import _remove_small_segments
from scan2morph.scan.stereo.sgbm import (
    _depth_to_disparity,
    _disparity_to_depth,
    _lr_consistent,
    _match_views,
    _pad_views,
    _sgbm_matcher,
)
from scan2morph.scan.stereo.windowed import _local_std

#: Nearest and farthest depth the coarse pass searches, mm.
_WIDE_DEPTH_MM = (200.0, 5000.0)
#: Largest search of the coarse pass at its own scale, px (sets the pyramid level).
_COARSE_DISPARITIES = 192
#: Widest coarse view, px (so a small search on a large image stays cheap too).
_COARSE_WIDTH = 512
#: Segments of consistent coarse disparities: largest step between 4-neighbours, coarse px.
_SEGMENT_STEP_PX = 1.0
#: Smallest segment that counts, as a fraction of the coarse left view's content ...
_MIN_SEGMENT_FRACTION = 0.005
#: ... and as a fraction of the largest segment.
_RELATIVE_SEGMENT = 0.1
#: Robust extent of a segment's disparities, percent.
_PERCENTILES = (1.0, 99.0)
#: Gaussian window of the coarse texture check, coarse px.
_COARSE_TEXTURE_SIGMA_PX = 1.0


@dataclass(frozen=True)
class _SearchDepths:
    """The depth range of the disparity search and where it came from.

    Attributes
    ----------
    depth_mm : (float or None, float or None)
        Nearest and farthest depth searched, mm (rectified left frame); ``None`` where the
        disparity range given in the parameters reaches infinity.
    source : str
        ``"derived"`` (the coarse pass) or ``"config"`` (the parameters).
    coarse_scale : int
        Pyramid factor of the coarse pass (``0`` when the range was not derived).
    """

    depth_mm: tuple[float | None, float | None]
    source: str
    coarse_scale: int = 0


def _search_depths(
    rect: Mapping[str, Any],
    left: np.ndarray,
    right: np.ndarray,
    valid_l: np.ndarray,
    valid_r: np.ndarray,
    p: Mapping[str, Any],
    source: str | PathLike[str],
) -> _SearchDepths:
    """The depth range of the fine disparity search: the parameters', else derived.

    Parameters
    ----------
    rect : mapping
        The rectification (``P1``, ``P2``).
    left, right : (Hr, Wr) uint8
        Rectified grey views, 0 outside the images.
    valid_l, valid_r : (Hr, Wr) bool
        Rectified pixels with image content.
    p : mapping
        Checked stereo parameters (``min_depth_mm``, ``max_depth_mm`` mm or both None,
        ``depth_margin_mm``, ``minDisparity``, ``numDisparities`` and the SGBM parameters).
    source : str or path-like
        Label named in errors.

    Returns
    -------
    _SearchDepths

    Raises
    ------
    InputError
        No range can be derived: the coarse pass finds no textured surface both views see.
    """
    if p["min_depth_mm"] is not None:
        return _SearchDepths((float(p["min_depth_mm"]), float(p["max_depth_mm"])), "config")
    if p["minDisparity"] is not None and p["numDisparities"] is not None:
        lo = int(p["minDisparity"])
        z = _disparity_to_depth(rect, [lo, lo + int(p["numDisparities"])])
        near, far = float(z.min()), float(z.max())
        return _SearchDepths((near, far if np.isfinite(far) else None), "config")
    return _derive(rect, (left, right, valid_l, valid_r), p, source)


def _derive(
    rect: Mapping[str, Any],
    views: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    p: Mapping[str, Any],
    source: str | PathLike[str],
) -> _SearchDepths:
    """Depth range of the surfaces the coarse pass finds (see the module), mm.

    ``views`` are ``(left, right, valid_l, valid_r)`` of :func:`_search_depths`; the other
    parameters and the errors as there.
    """
    wide = _wide_disparities(rect, views[2], views[3], source)
    width = views[0].shape[1]
    reduction = max((wide[1] - wide[0]) / _COARSE_DISPARITIES, width / _COARSE_WIDTH, 1.0)
    levels = int(np.ceil(np.log2(reduction)))
    scale = 2**levels
    views = _pyramid(*views, levels)
    disparity = _coarse_disparity(*views, wide / scale, p)
    extent = _surface_extent(disparity, views[2])
    if extent is None:
        raise InputError(
            source,
            "left/right: the images do not overlap as a stereo pair: no depth range could be "
            f"derived (no textured surface both views see at {_WIDE_DEPTH_MM[0]:g}-"
            f"{_WIDE_DEPTH_MM[1]:g} mm); check that left and right belong to this calibration "
            "and are textured, or set stereo min_depth_mm and max_depth_mm",
        )
    d = np.array([extent[0] * scale - scale, extent[1] * scale + scale])
    z = _disparity_to_depth(rect, d)
    z_wide = np.sort(_disparity_to_depth(rect, wide))
    near = float(z.min())
    far = float(min(z.max(), z_wide[1]))
    margin = float(p["depth_margin_mm"])
    lo = max(near - margin, 0.5 * near, float(z_wide[0]))
    hi = far + margin
    return _SearchDepths((lo, hi), "derived", scale)


def _wide_disparities(
    rect: Mapping[str, Any],
    valid_l: np.ndarray,
    valid_r: np.ndarray,
    source: str | PathLike[str],
) -> np.ndarray:
    """Disparities of depths ``_WIDE_DEPTH_MM`` that fit the rectified images, px, (2,).

    A match pairs a left column with content and a right one: its disparity lies between
    the leftmost left column minus the rightmost right one and the reverse.

    Raises
    ------
    InputError
        No disparity of those depths fits (the rectified views do not share columns).
    """
    d = np.sort(_depth_to_disparity(rect, np.array(_WIDE_DEPTH_MM)))
    cols_l = np.flatnonzero(valid_l.any(axis=0))
    cols_r = np.flatnonzero(valid_r.any(axis=0))
    if cols_l.size and cols_r.size:
        d = np.clip(d, cols_l[0] - cols_r[-1], cols_l[-1] - cols_r[0])
    if not (cols_l.size and cols_r.size) or d[1] - d[0] < 1.0:
        raise InputError(
            source,
            "calibration: expected views that can share a surface at "
            f"{_WIDE_DEPTH_MM[0]:g}-{_WIDE_DEPTH_MM[1]:g} mm, got rectified views that do not",
        )
    return d


def _pyramid(
    left: np.ndarray, right: np.ndarray, valid_l: np.ndarray, valid_r: np.ndarray, levels: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both views and their content masks ``levels`` times reduced by :func:`cv2.pyrDown`.

    Parameters
    ----------
    left, right : (Hr, Wr) uint8
        Rectified views.
    valid_l, valid_r : (Hr, Wr) bool
        Their content masks.
    levels : int
        Pyramid levels (>= 0); each halves both sides (rounding up).

    Returns
    -------
    left, right : (h, w) uint8
        Coarse views; coarse pixel ``x`` sits on full pixel ``2^levels x``.
    valid_l, valid_r : (h, w) bool
        Coarse pixels whose pyramid window holds only content.
    """
    masks = [valid_l.astype(np.float32), valid_r.astype(np.float32)]
    for _ in range(levels):
        left, right = cv2.pyrDown(left), cv2.pyrDown(right)
        masks = [cv2.pyrDown(m) for m in masks]
    return left, right, masks[0] > 0.999, masks[1] > 0.999


def _coarse_disparity(
    left: np.ndarray,
    right: np.ndarray,
    valid_l: np.ndarray,
    valid_r: np.ndarray,
    search: np.ndarray,
    p: Mapping[str, Any],
) -> np.ndarray:
    """Confirmed textured SGBM disparities of the coarse pair over ``search``, coarse px.

    Parameters
    ----------
    left, right : (h, w) uint8
        Coarse rectified views.
    valid_l, valid_r : (h, w) bool
        Their content masks.
    search : (2,) float
        Lowest and highest disparity searched, coarse px.
    p : mapping
        Checked stereo parameters (SGBM's, ``lr_max_diff_px``, ``min_texture``).

    Returns
    -------
    (h, w) float32
        Disparity of the coarse left view, coarse px; NaN where unmatched, inconsistent with
        the right view, untextured or in a speck.
    """
    min_disp = int(np.floor(search[0])) - 1
    num_disp = int(16 * np.ceil(max(np.ceil(search[1]) + 1 - min_disp, 16) / 16))
    left, right, pv_l, pv_r, pad_l, pad_r = _pad_views(
        left, right, valid_l, valid_r, min_disp, num_disp
    )
    matcher = _sgbm_matcher(p, min_disp, num_disp)
    disp_l16, disp_r16, min_disp_r = _match_views(matcher, left, right)
    matched_l = (disp_l16 >= 16 * min_disp) & pv_l
    matched_r = (disp_r16 >= 16 * min_disp_r) & pv_r
    consistent = _lr_consistent(disp_l16, disp_r16, matched_l, matched_r, p["lr_max_diff_px"])
    textured = _local_std(left, _COARSE_TEXTURE_SIGMA_PX, pv_l) >= float(p["min_texture"])
    disparity = np.where(consistent & textured, disp_l16.astype(np.float32) / 16.0, np.nan)
    disparity = _remove_small_segments(disparity.astype(np.float32), 16, _SEGMENT_STEP_PX)
    return disparity[:, pad_l : disparity.shape[1] - pad_r]


def _surface_extent(disparity: np.ndarray, valid_l: np.ndarray) -> tuple[float, float] | None:
    """Robust disparity extent of the surfaces found by the coarse pass, coarse px.

    Parameters
    ----------
    disparity : (h, w) float32
        Coarse left disparity, coarse px; NaN where there is none.
    valid_l : (h, w) bool
        Coarse left pixels with content.

    Returns
    -------
    (float, float) or None
        Lowest and highest disparity over the segments that count (see the module), coarse
        px; ``None`` when no segment counts.
    """
    labels, areas = _segments(disparity, _SEGMENT_STEP_PX)
    floor = max(_MIN_SEGMENT_FRACTION * np.count_nonzero(valid_l), 16.0)
    if areas.size == 0 or areas.max() < floor:
        return None
    keep = np.flatnonzero(areas >= max(floor, _RELATIVE_SEGMENT * areas.max())) + 1
    inside = np.isin(labels, keep)
    order = np.argsort(labels[inside], kind="stable")
    values = disparity[inside][order]
    starts = np.searchsorted(labels[inside][order], keep)
    ends = np.append(starts[1:], values.size)
    extents = np.array(
        [np.percentile(values[a:b], _PERCENTILES) for a, b in zip(starts, ends, strict=True)]
    )
    return float(extents[:, 0].min()), float(extents[:, 1].max())


def _segments(disparity: np.ndarray, step_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Segments of a disparity map: 4-connected pixels with steps of at most ``step_px``.

    Pixels next to a larger step (on both sides) belong to none, which separates surfaces
    that touch in the image at different depths.

    Parameters
    ----------
    disparity : (h, w) float32
        Disparity, px; NaN where there is none.
    step_px : float
        Largest disparity step between 4-neighbours of one segment, px.

    Returns
    -------
    labels : (h, w) int32
        Segment of every pixel (1-based), 0 none.
    areas : (n,) int
        Pixels of segments ``1..n``.
    """
    valid = np.isfinite(disparity)
    filled = np.where(valid, disparity, 0.0)
    cut = np.zeros_like(valid)
    jump_x = valid[:, 1:] & valid[:, :-1] & (np.abs(np.diff(filled, axis=1)) > step_px)
    jump_y = valid[1:] & valid[:-1] & (np.abs(np.diff(filled, axis=0)) > step_px)
    cut[:, 1:] |= jump_x
    cut[:, :-1] |= jump_x
    cut[1:] |= jump_y
    cut[:-1] |= jump_y
    _, labels, stats, _ = cv2.connectedComponentsWithStats(
        (valid & ~cut).astype(np.uint8), connectivity=4
    )
    return labels, stats[1:, cv2.CC_STAT_AREA]
