"""Settings of the range-image repair (:data:`DEFAULT_REPAIR`, :data:`DEFAULT_DEPTH_REPAIR`),
the checks of its inputs, and the pixel-window offsets the spike test and the hole filter share."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from scan2morph.errors import InputError

#: Default parameters of :func:`repair_range` (the ``repair`` section of the config).
DEFAULT_REPAIR: dict[str, float | int] = {
    "spike_threshold_mm": 5.0,
    "spike_window": 5,
    "max_hole_px": 400,
    "fill_kernel_px": 3,
    "fill_threshold": 0.2,
    "fill_max_iter": 100,
    "max_edge_hole_px": 50,
}
#: Default parameters used only for depth-camera data (``repair_range(..., depth_camera=True)``;
#: the same config section).
DEFAULT_DEPTH_REPAIR: dict[str, float | int] = {
    "depth_edge_jump_mm": 10.0,
    "depth_edge_trim_px": 16,
    "depth_smooth_sigma_px": 1.5,
}

#: Source named by parameter errors: the config section, whatever the take.
PARAMS_SOURCE = "repair"


def check_xyz(xyz: Any, source: str) -> tuple[np.ndarray, np.ndarray]:
    """Return ``xyz`` as a float64 copy with whole-pixel NaNs, and its (H, W) valid mask."""
    arr = np.asarray(xyz)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InputError(source, f"xyz: expected shape (H, W, 3), got {arr.shape}")
    if arr.shape[0] < 3 or arr.shape[1] < 3:
        raise InputError(source, f"xyz: expected H, W >= 3, got {arr.shape[:2]}")
    if arr.dtype.kind != "f":
        raise InputError(
            source, f"xyz: expected a float array (mm, NaN = no data), got {arr.dtype}"
        )
    arr = arr.astype(np.float64, copy=True)
    if np.isinf(arr).any():
        raise InputError(source, "xyz: expected finite values or NaN, got +-inf")
    valid = ~np.isnan(arr).any(axis=2)
    if not valid.any():
        raise InputError(source, "xyz: no valid pixel (all NaN)")
    arr[~valid] = np.nan  # a pixel is missing as a whole
    return arr, valid


def check_int(value: Any, name: str, source: str, *, minimum: int, odd: bool = False) -> int:
    """``value`` as an int of at least ``minimum`` (odd if ``odd``); ``name`` and ``source``
    name it in the error."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputError(source, f"{name}: expected an integer, got {value!r}")
    value = int(value)
    if value < minimum or (odd and value % 2 == 0):
        kind = "an odd integer" if odd else "an integer"
        raise InputError(source, f"{name}: expected {kind} >= {minimum}, got {value}")
    return value


def check_float(value: Any, name: str, source: str, *, upper: float | None = None) -> float:
    """``value`` as a finite float > 0 (and below ``upper`` if given); ``name`` and ``source``
    name it in the error."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(source, f"{name}: expected a number, got {value!r}")
    value = float(value)
    if not np.isfinite(value) or value <= 0 or (upper is not None and value >= upper):
        bound = f"in (0, {upper})" if upper is not None else "> 0"
        raise InputError(source, f"{name}: expected a finite number {bound}, got {value}")
    return value


def neighbour_offsets(
    width_padded: int, radius: int, *, centre: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Flat-index offsets, (dy, dx) pairs of a (2r+1)^2 window in a padded row-major image."""
    d = np.arange(-radius, radius + 1)
    dy, dx = np.meshgrid(d, d, indexing="ij")
    keep = np.ones(dy.shape, bool) if centre else (dy != 0) | (dx != 0)
    dy, dx = dy[keep], dx[keep]
    return dy * width_padded + dx, np.stack([dy, dx], axis=1)


__all__ = ["DEFAULT_DEPTH_REPAIR", "DEFAULT_REPAIR"]
