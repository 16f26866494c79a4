"""How precisely the landmarks were clicked, measured from a subject's own takes.

A stable landmark (the nose bridge, an eye corner) marks the same point of the face in every
take whose upper face is at rest: the neutral and the visemes. Lifted to 3D on each take's range
image and brought into the neutral frame by the pipeline's alignment, its clicks should
coincide; their scatter is the clicking (or detector) noise. For each click this module takes
the offset from the mean of the point's other clicks, maps it back into the take's image by the
local Jacobian of the range image (pixels per mm along the surface), and estimates the standard
deviation per image coordinate with the correction for that mean's own noise:

    sigma^2 = sum_i |r_i|^2 n_i / (n_i + 1) / (2 m)

over the m residuals ``r_i`` (px) of clicks compared with the mean of ``n_i`` others. Clicks
farther than :data:`OUTLIER_SIGMAS` times a first, median-based estimate are mis-clicks: removed
worst first, reported and left out.
The result feeds :func:`scan2morph.motion.uncertainty.click_noise_motion` when the config asks
for ``click_noise_px: auto``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from scan2morph.align.rigid import invert, transform_points
from scan2morph.errors import InputError
from scan2morph.motion.clicks import ClickedTake
from scan2morph.template.sample import sample_range

#: A residual beyond this many (median-estimated) standard deviations, radially, is a mis-click.
OUTLIER_SIGMAS = 4.0
#: Fewest residuals an estimate is made from.
MIN_RESIDUALS = 6


def _lift(take: ClickedTake, points: np.ndarray, max_slope_deg, source: str):
    """Clicks in the neutral frame (P, 3) and the range image's Jacobian at them (P, 3, 2)."""
    xyz = np.asarray(take.xyz, dtype=np.float64)
    clicks = np.asarray(take.landmarks, dtype=np.float64)[points - 1]
    at, _ = sample_range(xyz, clicks, source, max_slope_deg=max_slope_deg)
    steps = (np.array([0.5, 0.0]), np.array([0.0, 0.5]))
    jac = np.stack(
        [
            sample_range(xyz, clicks + s, source)[0] - sample_range(xyz, clicks - s, source)[0]
            for s in steps
        ],
        axis=-1,
    )
    return transform_points(np.asarray(take.transform, float), at), jac


def click_precision(
    takes: Mapping[str, ClickedTake],
    points: Sequence[int],
    max_slope_deg: float | None = None,
    source: str = "subject",
) -> dict:
    """Standard deviation of the landmark clicks (px per coordinate) from stable landmarks.

    Parameters
    ----------
    takes : mapping take -> ClickedTake
        Takes whose ``points`` mark the same face points (the neutral and the visemes), with
        their alignment to the neutral frame.
    points : sequence of int
        1-based iBUG numbers of the stable landmarks.
    max_slope_deg : float, optional
        The fit's depth-step rule: a click whose neighbour pixels straddle a steeper step is not
        lifted (its depth is not defined).
    source : str
        The subject, for messages.

    Returns
    -------
    dict
        ``click_noise_px``: the estimate, or None when fewer than :data:`MIN_RESIDUALS`
        residuals were available (``reason`` then says why); ``n_residuals``: residuals used;
        ``misclicks``: list of ``(take, iBUG number, residual px)`` left out;
        ``residual_px``: dict take -> (P,) float64 px, NaN where a click was not used.

    Raises
    ------
    InputError
        ``points`` outside 1..L of a take's landmarks.
    """
    names = list(takes)
    pts = np.asarray(points, dtype=np.int64).reshape(-1)
    for name in names:
        n_lm = len(takes[name].landmarks)
        if len(pts) and (pts.min() < 1 or pts.max() > n_lm):
            raise InputError(
                f"{source}/{name}",
                f"stable points: expected iBUG numbers 1..{n_lm}, got {pts.tolist()}",
            )
    out = {
        "click_noise_px": None,
        "n_residuals": 0,
        "misclicks": [],
        "residual_px": {n: np.full(len(pts), np.nan) for n in names},
        "reason": "",
    }
    if len(names) < 2 or not len(pts):
        out["reason"] = f"{len(names)} take(s) and {len(pts)} stable point(s): nothing to compare"
        return out
    lifted = {n: _lift(takes[n], pts, max_slope_deg, f"{source}/{n}") for n in names}
    frame = np.stack([lifted[n][0] for n in names])  # (T, P, 3) neutral frame
    inverse = [invert(np.asarray(takes[n].transform, float)) for n in names]
    jacs = np.stack([lifted[n][1] for n in names])  # (T, P, 3, 2)
    use = np.isfinite(frame).all(axis=2) & np.isfinite(jacs).all(axis=(2, 3))
    while True:
        count = use.sum(axis=0)
        mean = np.where(use[..., None], frame, 0.0).sum(axis=0) / np.maximum(count, 1)[:, None]
        # each click against the mean of the point's other clicks in use, in the take's pixels
        radius = np.full(use.shape, np.nan)
        weight = np.ones(use.shape)
        for t in range(len(names)):
            for k in np.flatnonzero(np.isfinite(frame[t]).all(axis=1) & (count >= 2)):
                n = count[k] - use[t, k]  # the other clicks
                others = (mean[k] * count[k] - use[t, k] * frame[t, k]) / n
                offset = inverse[t][:3, :3] @ (others - frame[t, k])  # in the take's frame
                du = np.linalg.lstsq(jacs[t, k], offset, rcond=None)[0]
                # |click - mean of the others| has variance (1 + 1/n) sigma^2 per coordinate
                radius[t, k], weight[t, k] = np.linalg.norm(du), n / (n + 1)
        scaled = radius * np.sqrt(weight)
        inside = use & np.isfinite(scaled)
        if inside.sum() < MIN_RESIDUALS:
            out["reason"] = (
                f"{int(inside.sum())} stable-landmark clicks with range data in two or more "
                f"takes (expected at least {MIN_RESIDUALS})"
            )
            return out
        # median of a 2D Gaussian's radius = sigma * sqrt(2 ln 2)
        rough = np.median(scaled[inside]) / np.sqrt(2.0 * np.log(2.0))
        worst = np.unravel_index(np.argmax(np.where(inside, scaled, -np.inf)), use.shape)
        if scaled[worst] <= OUTLIER_SIGMAS * rough:
            break
        # the worst mis-click leaves the means (it pulls its point's other residuals up too);
        # the rest are measured again without it
        use[worst] = False
    for t, name in enumerate(names):
        out["residual_px"][name] = np.where(inside[t], radius[t], np.nan)
        for k in np.flatnonzero(np.isfinite(frame[t]).all(axis=1) & ~use[t]):
            if np.isfinite(radius[t, k]):
                out["misclicks"].append((name, int(pts[k]), float(radius[t, k])))
    out["n_residuals"] = int(inside.sum())
    out["click_noise_px"] = float(np.sqrt(np.sum(scaled[inside] ** 2) / (2 * inside.sum())))
    return out


def resolve_click_noise(
    setting: float | str,
    takes: Mapping[str, ClickedTake],
    points: Sequence[int],
    fallback_px: float,
    max_slope_deg: float | None = None,
    source: str = "subject",
) -> dict:
    """The click noise the error bar uses: the configured value, or the measured one.

    Parameters
    ----------
    setting : float or "auto"
        ``motion_noise.click_noise_px``: a standard deviation in px, or ``"auto"`` to use
        :func:`click_precision` (``fallback_px`` when it cannot be measured).
    takes, points, max_slope_deg, source
        As :func:`click_precision` (measured in any case, as a check on a configured value).
    fallback_px : float
        Used with ``"auto"`` when too few stable clicks can be compared.

    Returns
    -------
    dict
        ``click_noise_px`` (used), ``measured_px`` (NaN when not measurable), ``source``
        (``"measured"``, ``"config"`` or ``"fallback"``), ``note`` (one line for logs and the
        report), ``misclicks`` (see :func:`click_precision`).

    Raises
    ------
    InputError
        ``setting`` neither a positive number nor ``"auto"``, or as :func:`click_precision`.
    """
    measured = click_precision(takes, points, max_slope_deg, source)
    px = measured["click_noise_px"]
    result = {
        "measured_px": float("nan") if px is None else px,
        "misclicks": measured["misclicks"],
    }
    seen = (
        f"measured {px:.2f} px on {measured['n_residuals']} stable-landmark clicks"
        if px is not None
        else f"not measurable: {measured['reason']}"
    )
    if setting == "auto":
        if px is not None:
            return result | {"click_noise_px": px, "source": "measured", "note": seen}
        note = f"assumed {fallback_px} px ({seen})"
        return result | {"click_noise_px": float(fallback_px), "source": "fallback", "note": note}
    if isinstance(setting, bool) or not isinstance(setting, (int, float)) or not setting > 0:
        raise InputError(
            source, f"motion_noise.click_noise_px: expected a number > 0 or 'auto', got {setting!r}"
        )
    note = f"configured {setting} px ({seen})"
    return result | {"click_noise_px": float(setting), "source": "config", "note": note}
