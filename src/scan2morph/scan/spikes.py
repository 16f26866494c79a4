"""Spikes of a range image (Yano-Harada section 3.1): isolated outliers set to NaN
(:func:`remove_spikes`).

A range image is ``xyz`` (H, W, 3) float64 in mm, NaN where the scanner saw nothing, in an
arbitrary right-handed scanner frame. Nothing here assumes which axis is depth: spikes are
judged by 3D distances to a neighbourhood median taken in the scanner's own frame (estimated
from the pixel grid, :func:`scan2morph.scan.view.scanner_view`), so a rigid motion of the data
moves the result with it.
"""

from __future__ import annotations

import numpy as np

from scan2morph.scan.settings import (
    DEFAULT_REPAIR,
    PARAMS_SOURCE,
    check_float,
    check_int,
    check_xyz,
    neighbour_offsets,
)
from scan2morph.scan.view import scanner_view

#: Neighbour pixels processed per chunk in remove_spikes (bounds memory to ~20 MB).
_SPIKE_CHUNK = 32768


def remove_spikes(
    xyz: np.ndarray,
    threshold_mm: float = DEFAULT_REPAIR["spike_threshold_mm"],
    window: int = DEFAULT_REPAIR["spike_window"],
    *,
    min_support: int = 4,
    source: str = "repair",
) -> tuple[np.ndarray, np.ndarray]:
    """Set isolated outliers ("spikes") of a range image to NaN.

    A valid pixel is a spike when its 3D distance to the median of its ``window`` x ``window``
    neighbourhood (per-coordinate median over the valid neighbours, the pixel itself excluded,
    in the scanner's frame: :func:`~scan2morph.scan.view.scanner_view`)
    exceeds ``threshold_mm``, and fewer than ``min_support`` of its valid neighbours lie within
    ``threshold_mm`` of it. The second test keeps the rim of a foreground surface in front of
    another valid surface: there the neighbourhood median may come from the far surface, but the
    rim pixel is backed by its own surface's neighbours, which a spike is not. Pixels with fewer
    than ``max(3, (window**2 - 1) // 4)`` valid neighbours are left alone.

    Parameters
    ----------
    xyz : (H, W, 3) float ndarray, mm
        Range image, NaN where there is no data. Not modified.
    threshold_mm : float, mm
        Distance from the neighbourhood median above which a pixel may be a spike.
    window : int
        Odd side length of the square neighbourhood, pixels.
    min_support : int
        A pixel with at least this many valid neighbours within ``threshold_mm`` is kept.
    source : str
        Names the data in ``xyz`` errors (a file or ``subject/take``); parameter errors name
        the config section ``repair``.

    Returns
    -------
    xyz_clean : (H, W, 3) float64 ndarray, mm
        Copy of ``xyz`` with the spikes set to NaN.
    spikes : (H, W) bool ndarray
        True at the pixels removed.

    Raises
    ------
    InputError
        If ``xyz`` is not an (H, W, 3) float array with some valid pixel, or a parameter is
        out of range.
    """
    arr, valid = check_xyz(xyz, source)
    threshold_mm = check_float(threshold_mm, "threshold_mm", PARAMS_SOURCE)
    window = check_int(window, "window", PARAMS_SOURCE, minimum=3, odd=True)
    # The per-coordinate median turns with the frame: take it in the scanner's own frame
    # (estimated from the pixel grid; the conventional frame is used as it is).
    view = scanner_view(arr)
    data = (arr - view.centre) @ view.rotation.T if view.estimated else arr
    min_support = check_int(min_support, "min_support", PARAMS_SOURCE, minimum=1)
    r = window // 2
    h, w = valid.shape
    # coordinate-major padded copy: gathers give (3, n, K) rows contiguous along K
    pad = np.pad(data, ((r, r), (r, r), (0, 0)), constant_values=np.nan)
    pad = np.ascontiguousarray(pad.reshape(-1, 3).T)
    offsets, _ = neighbour_offsets(w + 2 * r, r, centre=False)
    min_valid = max(3, (window * window - 1) // 4)

    ys, xs = np.nonzero(valid)
    centres = (ys + r) * (w + 2 * r) + (xs + r)
    is_spike = np.zeros(centres.size, bool)
    for start in range(0, centres.size, _SPIKE_CHUNK):  # chunks bound memory, not a pixel loop
        c = centres[start : start + _SPIKE_CHUNK]
        nb = pad[:, c[:, None] + offsets[None, :]]  # (3, n, K)
        n_valid = np.count_nonzero(~np.isnan(nb[0]), axis=1)  # (n,)
        srt = np.sort(nb, axis=2)  # NaNs sort last
        lo = np.broadcast_to(np.maximum(n_valid - 1, 0)[None, :, None] // 2, (3, c.size, 1))
        hi = np.broadcast_to(n_valid[None, :, None] // 2, (3, c.size, 1))
        med = (
            0.5
            * (np.take_along_axis(srt, lo, axis=2) + np.take_along_axis(srt, hi, axis=2))[:, :, 0]
        )  # (3, n)
        p = pad[:, c]  # (3, n)
        dist2 = ((p - med) ** 2).sum(axis=0)
        cand = np.flatnonzero((dist2 > threshold_mm**2) & (n_valid >= min_valid))
        # support: valid neighbours within threshold_mm of the candidate itself
        nd2 = ((nb[:, cand, :] - p[:, cand, None]) ** 2).sum(axis=0)  # (m, K), NaN if invalid
        support = np.count_nonzero(nd2 <= threshold_mm**2, axis=1)
        is_spike[start + cand[support < min_support]] = True

    spikes = np.zeros((h, w), bool)
    spikes[ys[is_spike], xs[is_spike]] = True
    arr[spikes] = np.nan
    return arr, spikes


__all__ = ["remove_spikes"]
