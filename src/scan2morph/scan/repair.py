"""Range-image repair (Yano-Harada section 3.1): spikes removed (:mod:`scan2morph.scan.spikes`),
then small holes filled (:mod:`scan2morph.scan.holes`); for a depth camera the far side of depth
edges dropped first and the depth noise smoothed after the spikes
(:mod:`scan2morph.scan.depth_cleanup`). :func:`repair_range` runs them with the ``repair``
section's settings (:mod:`scan2morph.scan.settings`).
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from scan2morph.errors import InputError
from scan2morph.scan.depth_cleanup import smooth_depth, trim_depth_edges
from scan2morph.scan.holes import fill_holes
from scan2morph.scan.settings import (
    DEFAULT_DEPTH_REPAIR,
    DEFAULT_REPAIR,
    PARAMS_SOURCE,
    check_float,
    check_int,
    check_xyz,
)
from scan2morph.scan.spikes import remove_spikes


def repair_range(
    xyz: np.ndarray,
    params: dict[str, Any] | None = None,
    *,
    source: str = "repair",
    depth_camera: bool = False,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Remove spikes, then fill small holes, of a range image.

    With ``depth_camera`` (RGB-D data) the far side of depth edges is dropped first
    (:func:`trim_depth_edges`: flying pixels) and the depth noise is smoothed after the spike
    removal (:func:`smooth_depth`).

    Parameters
    ----------
    xyz : (H, W, 3) float ndarray, mm
        Range image, NaN where there is no data. Not modified.
    params : dict, optional
        Any of the keys of :data:`DEFAULT_REPAIR` and :data:`DEFAULT_DEPTH_REPAIR`
        (``spike_threshold_mm``, ``spike_window``,
        ``max_hole_px``, ``fill_kernel_px``, ``fill_threshold``, ``fill_max_iter``,
        ``max_edge_hole_px``, and for depth cameras ``depth_edge_jump_mm``,
        ``depth_edge_trim_px``, ``depth_smooth_sigma_px``); missing keys take the defaults.
    source : str
        Names the data in ``xyz`` errors (a file or ``subject/take``); parameter errors name
        the config section ``repair``.

    Returns
    -------
    xyz_repaired : (H, W, 3) float64 ndarray, mm
        Copy of ``xyz`` without spikes and with small holes filled.
    report : dict
        The :func:`fill_holes` report plus ``spikes`` ((H, W) bool) and ``n_spikes`` (int).
        ``filled`` marks pixels whose values were interpolated (spikes included, when their
        hole was filled); ``flying`` ((H, W) bool, pixels dropped at depth edges) and
        ``n_flying``.

    Raises
    ------
    InputError
        Unknown or out-of-range parameters (source ``"repair"``), or a bad ``xyz``.
    """
    params = {} if params is None else params
    if not isinstance(params, dict):
        raise InputError(PARAMS_SOURCE, f"params: expected a dict, got {type(params).__name__}")
    known = DEFAULT_REPAIR | DEFAULT_DEPTH_REPAIR
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise InputError(
            PARAMS_SOURCE, f"params: unknown key(s) {unknown}, expected some of {sorted(known)}"
        )
    p = {**known, **params}
    for key in ("spike_window", "fill_kernel_px"):
        check_int(p[key], f"params.{key}", PARAMS_SOURCE, minimum=3, odd=True)
    for key in ("max_hole_px", "fill_max_iter"):
        check_int(p[key], f"params.{key}", PARAMS_SOURCE, minimum=1)
    check_int(p["max_edge_hole_px"], "params.max_edge_hole_px", PARAMS_SOURCE, minimum=0)
    check_float(p["spike_threshold_mm"], "params.spike_threshold_mm", PARAMS_SOURCE)
    check_float(p["fill_threshold"], "params.fill_threshold", PARAMS_SOURCE, upper=1.0)
    check_float(p["depth_edge_jump_mm"], "params.depth_edge_jump_mm", PARAMS_SOURCE)
    check_int(p["depth_edge_trim_px"], "params.depth_edge_trim_px", PARAMS_SOURCE, minimum=0)
    if not isinstance(p["depth_smooth_sigma_px"], numbers.Real) or p["depth_smooth_sigma_px"] < 0:
        raise InputError(PARAMS_SOURCE, "params.depth_smooth_sigma_px: expected a number >= 0")
    flying = np.zeros(np.shape(xyz)[:2], bool)
    if depth_camera:
        xyz = check_xyz(xyz, source)[0]
        xyz, flying = trim_depth_edges(xyz, p["depth_edge_jump_mm"], p["depth_edge_trim_px"])
    clean, spikes = remove_spikes(xyz, p["spike_threshold_mm"], p["spike_window"], source=source)
    if depth_camera:
        clean = smooth_depth(clean, p["depth_smooth_sigma_px"], p["depth_edge_jump_mm"])
    out, report = fill_holes(
        clean,
        p["max_hole_px"],
        p["fill_kernel_px"],
        p["fill_threshold"],
        p["fill_max_iter"],
        max_edge_hole_px=p["max_edge_hole_px"],
        source=source,
    )
    report.update(spikes=spikes, n_spikes=int(spikes.sum()))
    if depth_camera:
        report.update(flying=flying, n_flying=int(flying.sum()))
    return out, report


# fill_holes, remove_spikes, smooth_depth and trim_depth_edges live in modules of their own and
# stay importable from here.
__all__ = [
    "DEFAULT_REPAIR",
    "DEFAULT_DEPTH_REPAIR",
    "fill_holes",
    "remove_spikes",
    "repair_range",
    "smooth_depth",
    "trim_depth_edges",
]
