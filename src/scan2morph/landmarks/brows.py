"""The brows of a doubtful detection placed on the eyebrows' dark bands: :func:`fit_brows`.

iBUG's brow points (18-22 and 23-27) run along each eyebrow, a band of hair 5-10 mm wide that is
darker than the skin above and below it. On the real head the cascade, trained on synthetic
faces only, puts the brows 15 px too high (median over its renders at about 1.6 px per mm) and
arches them more than the real brows are, and the template fit takes its brow points: a fit
stretched up by them puts the forehead's vertices beyond a stereo scan's data. The eyebrows
themselves are plain in the colour image. :func:`fit_brows` lays a smooth curve over each
detected brow (the chord between its end points, the ends raised or lowered, an arch) where it
runs along the middle of the darkest band: the luminance ``L*`` on the curve against the skin
beside it, above and below, on the side where the curve is less dark (a band darker than both
sides, not the edge of a dark area). The five points are then spaced along the curve evenly by
their chord: where a brow ends (which the band's contrast does not tell) stays the detector's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import map_coordinates

from scan2morph.landmarks.image_fit import ascend, region, smoothed_channel

#: Each brow's points in iBUG-68 order (0-based): the right brow (the image's left), the left;
#: and both.
BROWS = (slice(17, 22), slice(22, 27))
SPAN = slice(17, 27)
#: Samples along a brow's curve (and along the detected polyline, for the contrast before).
SAMPLES = 24
#: The luminance's smoothing (Gaussian sigma) as a share of the brow's chord (about 1.5 mm).
SMOOTHING = 0.035
#: Where the skin beside the band is read: this share of the longer brow's chord above and below
#: the curve (about 6 mm: beyond a band's half width of 2.5-5 mm; the longer chord, as a turned
#: face's far brow is foreshortened along its chord, not across it).
BESIDE = 0.13
#: How far the curve may go from the chord, as a share of the chord: its ends and its arch up or
#: down (the detections' brows lie 5-13 mm off on the real head: 0.1-0.4 of a brow).
REACH = 0.45
#: The grid searched first (the ends' common shift, a share of the chord, in these steps; with
#: the arches :data:`ARCHES`), then the coordinate search's steps (shares of the chord).
GRID = 0.025
ARCHES = (0.0, 0.05, 0.1)
STEPS = (0.04, 0.02, 0.01)
#: The share of a curve's samples that must lie within the image (a brow's end may lie beyond
#: it: the contrast is the mean over the samples within).
MIN_INSIDE = 0.8
#: Below this contrast at the fitted place (how much darker ``L*`` is on the curve than beside it
#: on its less dark side, in standard deviations of ``L*`` about the brows) a brow's band was not
#: found, and then neither brow moves (the pair moves together: a face whose one brow is found and
#: the other not is not seen well enough, and a subject's takes must agree). The real head's brows
#: give 0.70-1.74 (the lower brow of each pair: its colour renders, its mesh, range, RGB-D and
#: texture-shot stereo takes), the synthetic heads' range takes 0.9-1.0. A grey image (every
#: channel equal: the shading of a geometry-only scan, which shows no hair) is not searched.
MIN_CONTRAST = 0.3
#: ... nor below this many times the standard deviation of the image's texture finer than the
#: smoothing (same units). The real head's brows give 5.6-13 times the fine texture of its skin
#: (the synthetic range takes' 5.4-6.3 at 640 x 480, 3.7 at 320 x 240, where the skin's freckles
#: span fewer pixels); under a stereo rig's projected speckle, which varies at
#: the fine scale as much as the brows' band does at the coarse one, the pair's best gives up to
#: 2.6 (a speckled neutral's brows once reached 0.67 in contrast while its smile's found none, and
#: the subject's takes then disagreed: the smile was left out, its refinement 10.5 mm from its
#: fit).
MIN_SIGNAL = 3.2


#: Below this standard deviation of the smoothed ``L*`` about the brows (8-bit levels) the image
#: is flat, a colour camera's noise alone (0.1-0.3 levels once smoothed), and the points stay;
#: faces give 25-60 (the real head's renders and the synthetic takes).
MIN_SPREAD = 2.0
#: Where a curve is sampled: shares of its chord.
_ALONG = np.linspace(0.0, 1.0, SAMPLES)


@dataclass(frozen=True)
class BrowFit:
    """A detection's brows placed by :func:`fit_brows`.

    Attributes
    ----------
    points : (68, 2) float64
        The landmarks, px; only the 10 brow points (iBUG 18-27) differ from the given ones.
    moved_px : float
        The median distance the 10 brow points moved, px (0: no band to follow).
    contrast_before, contrast_after : (2,) float64
        Each brow's contrast (:data:`MIN_CONTRAST`'s) at the detected and at the fitted place;
        ``contrast_after`` is ``contrast_before`` where the brows stay (a pair refused, a brow
        already on its band), and both are 0 where nothing was measured (a grey, flat or too
        small image, brows shorter than 8 px or not finite).
    """

    points: np.ndarray
    moved_px: float
    contrast_before: np.ndarray
    contrast_after: np.ndarray


def _luminance(color: np.ndarray, box: tuple, chord: float):
    """The smoothed, standardised ``L*`` of the region ``box``, and the standard deviation of the
    texture finer than the smoothing in the same units; None for a grey image (no hair to see)
    or a flat one (:data:`MIN_SPREAD`)."""
    read = smoothed_channel(color, box, 0, SMOOTHING * chord, MIN_SPREAD)
    if read is None:
        return None
    light, raw, spread = read
    return (light - light.mean()) / spread, float((raw - light).std()) / spread


class _Brow:
    """One detected brow, the curves laid over it and their contrast on ``light`` (whose pixel
    (0, 0) is the image's ``lo``)."""

    def __init__(self, brow: np.ndarray, light: np.ndarray, region: tuple, scale: float):
        self.brow, self.light = brow, light
        self.lo, self.hi = region
        self.scale = scale  # px: the longer brow's chord (a turned face's far brow is short)
        along = brow[-1] - brow[0]
        self.chord = float(np.linalg.norm(along))
        self.u = along / self.chord
        # across the chord, pointing up the image (y falling)
        self.up = np.array([self.u[1], -self.u[0]]) * (1.0 if self.u[0] >= 0 else -1.0)

    def curve(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(len(s), 2) px: the points at shares ``s`` of the chord of the curve whose ends are
        raised by ``t[0]`` and ``t[1]`` and whose middle is arched by ``t[2]`` (px)."""
        raised = t[0] * (1.0 - s) + t[1] * s + t[2] * 4.0 * s * (1.0 - s)
        return self.brow[0] + np.outer(s * self.chord, self.u) + np.outer(raised, self.up)

    def contrast(self, samples: np.ndarray) -> float:
        """How much darker ``L*`` is on the line through ``samples`` (n, 2) px than beside it,
        on the side where it is less so: the smaller of the mean differences above and below
        the line (a band darker than both sides scores; a step from dark to light does not),
        over the samples within the region read (at least :data:`MIN_INSIDE` of them; -inf
        otherwise)."""
        ahead = np.gradient(samples, axis=0)
        normal = np.stack([ahead[:, 1], -ahead[:, 0]], axis=1)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
        inside = ((samples >= self.lo) & (samples <= self.hi)).all(axis=1)
        if inside.mean() < MIN_INSIDE:
            return -np.inf
        on = samples[inside] - self.lo
        beside = BESIDE * self.scale * normal[inside]
        read = [on, on + beside, on - beside]
        line, a, b = (
            map_coordinates(self.light, [p[:, 1], p[:, 0]], order=1, mode="nearest") for p in read
        )
        return float(min(np.mean(a - line), np.mean(b - line)))

    def value(self, t: np.ndarray) -> float:
        """The contrast of the curve ``t``; -inf beyond :data:`REACH`."""
        if np.abs(t).max() > REACH * self.chord:
            return -np.inf
        return self.contrast(self.curve(t, _ALONG))

    def fit(self) -> tuple[np.ndarray, float, float]:
        """The brow's points on its band (as detected when no band stands out), and the
        contrast before and after."""
        segments = zip(self.brow[:-1], self.brow[1:], strict=True)
        per = SAMPLES // (len(self.brow) - 1)
        detected = np.concatenate([np.linspace(a, b, per, endpoint=False) for a, b in segments])
        before = self.contrast(detected)
        # the band may lie a band's width or more away, where the contrast at the detected
        # place says nothing of it: a grid over the ends' common shift and the arch first
        n = int(np.floor(REACH / GRID + 1e-9))
        grid = [
            np.array([y, y, arch]) * self.chord
            for y in GRID * np.arange(-n, n + 1)
            for arch in ARCHES
        ]
        scores = [self.value(g) for g in grid]
        start = grid[int(np.argmax(scores))]
        best, after = ascend(self.value, start, max(scores), np.full(3, self.chord), STEPS)
        if not after > before:  # the detection lies on the band already, or none is seen
            return self.brow, before, before
        # the points evenly spaced along the chord, as iBUG spaces them (the detected spacing
        # of a misplaced brow is no better: 4.8 against 4.6 px on the real head's renders)
        return self.curve(best, np.linspace(0.0, 1.0, len(self.brow))), before, after


def fit_brows(color: np.ndarray, points: np.ndarray) -> BrowFit:
    """Move each detected brow onto its eyebrow's dark band.

    Parameters
    ----------
    color : (H, W, 3) or (H, W, 4) array
        The take's colour image (RGB, uint8; floats in [0, 1] and wider integers are scaled) on
        its pixel grid; a grey image (every channel equal, or one channel) keeps the points.
    points : (68, 2) float
        The detected iBUG-68 points, px (x right, y down).

    Returns
    -------
    BrowFit
        The points with each brow's five laid on the curve (the chord through its end points,
        the ends raised or lowered and the curve arched by up to 0.45 of the chord each) that
        is darkest against the skin 0.13 of the longer chord above and below it
        (:data:`BESIDE`, the less dark side counting): a grid over the shift and the arch, then
        a coordinate search (:data:`STEPS`). A brow whose best contrast is not above the
        detection's stays; when either brow's is below :data:`MIN_CONTRAST`, or either is
        shorter than 8 px, both stay.
    """
    points = np.asarray(points, dtype=np.float64)
    brows = [points[s] for s in BROWS]
    chords = [float(np.linalg.norm(b[-1] - b[0])) for b in brows]
    same = BrowFit(points, 0.0, np.zeros(2), np.zeros(2))  # nothing measured
    if color.ndim != 3 or color.shape[2] < 3 or not np.isfinite(points[SPAN]).all():
        return same
    if min(chords) < 8.0:
        return same
    # every curve (its ends and its arch each up to REACH: 2 REACH off the chord at most) and
    # what it reads beside it, within the image
    box = region(points[SPAN], (2.0 * REACH + BESIDE) * max(chords), color.shape)
    seen = None if box is None else _luminance(color, box, float(np.mean(chords)))
    if seen is None:
        return same
    light, texture = seen
    fits = [_Brow(brow, light, box, max(chords)).fit() for brow in brows]
    before, after = np.array([f[1] for f in fits]), np.array([f[2] for f in fits])
    # a brow without its band, or bands no darker than the image's fine texture varies (a
    # projected speckle): the pair stays
    if (after < max(MIN_CONTRAST, MIN_SIGNAL * texture)).any():
        return BrowFit(points, 0.0, before, before)
    out = points.copy()
    for s, fit in zip(BROWS, fits, strict=True):
        out[s] = fit[0]
    moved = float(np.median(np.linalg.norm(out[SPAN] - points[SPAN], axis=1)))
    return BrowFit(out, moved, before, after)
