"""A lip's profile in an image: redness along it, the vermilion border (the steepest fall of
redness going outward), the length along the surface, and the registration of one image's
border to another's by the redness around it (:mod:`scan2morph.refine.lip` places the lip's
vertices with them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from scan2morph.errors import InputError
from scan2morph.refine.template_space import pull_back
from scan2morph.scan.view import ScannerView
from scan2morph.template.sample import sample_range

#: Spacing of a profile's samples, px.
STEP_PX = 0.2
#: Smoothing of a profile's redness, and of its surface points before their length is taken
#: (range noise of 0.1 mm on 0.2 px steps would otherwise add to the length), px.
RED_SIGMA_PX = 0.5
XYZ_SIGMA_PX = 1.0

#: Step of the registration's shifts, mm; least correlation of a registration; least share of
#: the neutral's profile the take's must cover at a shift for it to be scored.
SHIFT_STEP_MM = 0.05
MIN_CORRELATION = 0.8
MIN_COVER = 0.6


def redness(color: np.ndarray, source: str = "colour image") -> np.ndarray:
    """``R / (R + G + B)`` of an (H, W, 3) colour image, float64 (NaN where black).

    Raises
    ------
    InputError
        ``color`` is not (H, W, 3) (``source`` names it).
    """
    c = np.asarray(color, dtype=np.float64)
    if c.ndim != 3 or c.shape[2] != 3:
        raise InputError(source, f"colour: expected an (H, W, 3) RGB image, got shape {c.shape}")
    total = c.sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, c[..., 0] / total, np.nan)


def vermilion_edge(
    red: np.ndarray, t: np.ndarray, at: float, window: float, end: float | None = None
) -> tuple[float, float] | None:
    """The vermilion border along a lip profile: the steepest fall of redness going outward.

    Parameters
    ----------
    red : (n,) float
        Redness along the profile, from the slit (first) outward (smoothed).
    t : (n,) float
        The samples' position along the profile, increasing (0 at the slit vertex, 1 at the
        border vertex).
    at, window : float
        The border is looked for where ``|t - at| < window``.
    end : float, optional
        The skin's side is measured up to here (default: the profile's end), so that two
        profiles of different lengths compare the same skin.

    Returns
    -------
    (t_edge, contrast) or None
        The border's position and the redness step there: the mean redness from ``t = 0`` to
        the edge minus the mean beyond it (to ``end``). None when the profile has fewer than 3
        finite samples, the window holds none, or either side has none.

    Raises
    ------
    InputError
        ``red`` and ``t`` are not 1-D of the same length, or ``t`` does not increase.
    """
    r = np.asarray(red, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if r.ndim != 1 or t.shape != r.shape:
        raise InputError(
            "lip profile", f"red {r.shape} and t {t.shape}: expected 1-D arrays of one length"
        )
    if len(t) > 1 and not (np.diff(t) > 0).all():
        raise InputError("lip profile", "t: expected increasing positions along the profile")
    if np.isfinite(r).sum() < 3:
        return None
    grad = np.gradient(r, t)
    look = (np.abs(t - at) < window) & np.isfinite(grad)
    if not look.any():
        return None
    k = np.flatnonzero(look)[np.argmin(grad[look])]
    lip = r[(t >= 0.0) & (t < t[k])]
    skin = r[(t > t[k]) & (t <= (np.inf if end is None else end))]
    lip, skin = lip[np.isfinite(lip)], skin[np.isfinite(skin)]
    if len(lip) == 0 or len(skin) == 0:
        return None
    return float(t[k]), float(lip.mean() - skin.mean())


@dataclass(frozen=True)
class LipImage:
    """One image a lip is seen in, with the rules its range image is sampled by.

    Attributes
    ----------
    red : (H, W) float
        Redness (:func:`redness`); float32 spares each profile converting it
        (:func:`~scan2morph.refine.template_space.pull_back` samples float32).
    xyz : (H, W, 3) float
        The range image, pixel to pixel with it, mm (NaN: no data).
    view : ScannerView or None
        Its scanner's view for the depth-step rule (None: no rule, or estimated when sampled).
    min_weight, max_slope_deg : float
        The range image's sampling rules (:func:`~scan2morph.template.sample.sample_range`).
    source : str
        ``subject/take``, for messages.
    """

    red: np.ndarray
    xyz: np.ndarray
    view: ScannerView | None
    min_weight: float
    max_slope_deg: float | None
    source: str


def lip_profile(image: LipImage, origin, direction, start: float, end: float) -> tuple:
    """Samples of ``image`` along the line ``origin + t direction`` (px; (2,) each), ``t`` in
    ``[start, end]``: ``t`` (n,), smoothed redness (n,), surface points (n, 3) mm smoothed along
    it (NaN where the range has none), pixel positions (n, 2). The line is sampled 3 sigma
    further at both ends and trimmed after smoothing: a one-sided smoothing would pull the ends
    in."""
    height = float(np.linalg.norm(direction))
    pad = 3.0 * max(RED_SIGMA_PX, XYZ_SIGMA_PX) / height
    span = end - start + 2 * pad
    n = max(int(np.ceil(span * height / STEP_PX)), 8)
    t = np.linspace(start - pad, end + pad, n)
    px = origin + t[:, None] * direction
    step = span * height / (n - 1)
    r = pull_back(image.red, px[None])[0].astype(np.float64)
    r = _smooth(r, RED_SIGMA_PX / step)
    points, ok = sample_range(
        image.xyz, px, image.source, image.min_weight, image.max_slope_deg, image.view
    )
    points = np.where(ok[:, None], points, np.nan)
    points = _smooth(points, XYZ_SIGMA_PX / step)
    keep = (t >= start - 1e-9) & (t <= end + 1e-9)
    return t[keep], r[keep], points[keep], px[keep]


def _smooth(values: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing along a profile (n,) or each column of profiles (n, k), normalised
    over its finite samples (so neither a gap nor an end pulls it); NaN stays NaN."""
    bad = ~np.isfinite(values)
    v = np.where(bad, 0.0, values)
    w = gaussian_filter1d((~bad).astype(np.float64), sigma, axis=0, mode="constant")
    out = gaussian_filter1d(v, sigma, axis=0, mode="constant") / np.maximum(w, 1e-12)
    out[bad] = np.nan
    return out


def arc_length(t: np.ndarray, xyz: np.ndarray, t0: float) -> np.ndarray:
    """(n,) signed length along a profile's surface points (n, 3) from its point at ``t0``
    (positive for ``t > t0``), mm; NaN beyond the first gap on either side."""
    k = int(np.clip(np.searchsorted(t, t0) - 1, 0, len(t) - 2))
    p0 = np.array([np.interp(t0, t, xyz[:, j]) for j in range(3)])
    seg = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    out = np.full(len(t), np.nan)
    out[k + 1 :] = np.linalg.norm(xyz[k + 1] - p0) + np.concatenate(
        [[0.0], np.cumsum(seg[k + 1 :])]
    )
    out[: k + 1] = -(
        np.linalg.norm(p0 - xyz[k]) + np.concatenate([[0.0], np.cumsum(seg[:k][::-1])])
    )[::-1]
    return out


def register_redness(arc_n, red_n, arc_t, red_t, limit):
    """The shift (mm) that best aligns the take's redness profile to the neutral's: the
    neutral's redness at length ``a`` from its border matches the take's at ``a + shift``
    (zero-mean normalised correlation over their overlap, shifts within ``limit``); None
    without a clear match: a best correlation under :data:`MIN_CORRELATION`, or one at the
    edge of the shifts scored (the best may lie beyond)."""
    n_ok = np.isfinite(arc_n) & np.isfinite(red_n)
    t_ok = np.isfinite(arc_t) & np.isfinite(red_t)
    if n_ok.sum() < 8 or t_ok.sum() < 8:
        return None
    grid, ref = arc_n[n_ok], red_n[n_ok]
    at, rt = arc_t[t_ok], red_t[t_ok]
    m = int(np.floor(limit / SHIFT_STEP_MM))
    shifts = SHIFT_STEP_MM * np.arange(-m, m + 1)
    where = grid[None, :] + shifts[:, None]
    inside = (where >= at[0]) & (where <= at[-1])
    moved = np.where(inside, np.interp(where, at, rt), np.nan)
    score = _correlations(ref, moved, inside)
    if not np.isfinite(score).any():
        return None
    k = int(np.nanargmax(score))
    if not (0 < k < len(shifts) - 1 and np.isfinite(score[[k - 1, k + 1]]).all()):
        return None  # the best lies at the edge of what was scored
    if score[k] < MIN_CORRELATION:
        return None
    shift = shifts[k]
    c = score[k - 1] - 2 * score[k] + score[k + 1]
    if c < 0:
        shift += 0.5 * (score[k - 1] - score[k + 1]) / c * SHIFT_STEP_MM
    return float(shift)


def _correlations(ref: np.ndarray, moved: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Zero-mean normalised correlation of ``ref`` (n,) with each row of ``moved`` (s, n) over
    the row's samples ``inside`` (s, n) bool: (s,), NaN for a row covering under
    :data:`MIN_COVER` of ``ref`` or without variation. All rows at once (a loop over the
    shifts took a fifth of a refinement)."""
    score = np.full(len(moved), np.nan)
    rows = np.flatnonzero(inside.mean(axis=1) >= MIN_COVER)
    if not len(rows):
        return score
    keep = inside[rows]
    count = keep.sum(axis=1, keepdims=True)
    r = np.where(keep, ref[None, :], 0.0)
    m = np.where(keep, moved[rows], 0.0)
    a = np.where(keep, r - r.sum(axis=1, keepdims=True) / count, 0.0)
    b = np.where(keep, m - m.sum(axis=1, keepdims=True) / count, 0.0)
    den = np.sqrt(np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b))
    ok = den > 0
    score[rows[ok]] = np.einsum("ij,ij->i", a[ok], b[ok]) / den[ok]
    return score


__all__ = ["LipImage", "arc_length", "lip_profile", "redness", "register_redness", "vermilion_edge"]
