"""Parameters of the stereo reconstruction: :data:`DEFAULT_STEREO` and their checks."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2

from scan2morph.errors import InputError
from scan2morph.scan.stereo.rectify import INTERPOLATIONS

#: Default parameters of :func:`~scan2morph.scan.stereo.reconstruct_stereo`. SGBM parameters
#: carry OpenCV's names (see :func:`cv2.StereoSGBM_create`); ``None`` means "derive it" as
#: documented there.
DEFAULT_STEREO: dict[str, Any] = {
    # disparity search range: from the depth range; None derives it from the pair (a coarse
    # pass: scan2morph.scan.stereo.depth_range)
    "min_depth_mm": None,  # nearest expected surface, mm; None: derived (with max_depth_mm)
    "max_depth_mm": None,  # farthest expected surface, mm; None: derived
    "depth_margin_mm": 100.0,  # derived range: depth added before and behind the surfaces, mm
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
    "patch_curvature": True,  # bend the window with the disparity's curvature (False: planes)
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
    "rectify_interpolation": "lanczos4",  # "linear", "cubic" or "lanczos4" (least bias)
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
    depths = (p["min_depth_mm"], p["max_depth_mm"])
    if (depths[0] is None) != (depths[1] is None) or (
        depths[0] is not None and not 0 < depths[0] < depths[1]
    ):
        raise InputError(
            source,
            "min_depth_mm, max_depth_mm: expected 0 < min < max (mm) or both null (derived), "
            f"got {depths[0]}, {depths[1]}",
        )
    if not p["depth_margin_mm"] >= 0:
        raise InputError(source, f"depth_margin_mm: expected >= 0, got {p['depth_margin_mm']}")
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
    if p["rectify_interpolation"] not in INTERPOLATIONS:
        raise InputError(
            source,
            f"rectify_interpolation: expected one of {', '.join(INTERPOLATIONS)}, "
            f"got {p['rectify_interpolation']!r}",
        )
    if not isinstance(p["patch_curvature"], bool):
        raise InputError(
            source, f"patch_curvature: expected true or false, got {p['patch_curvature']!r}"
        )
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


__all__ = ["DEFAULT_STEREO", "stereo_params"]
