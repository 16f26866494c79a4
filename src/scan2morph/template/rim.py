"""The forehead rim of a take's fit, anchored to the neutral's by the take's still points.

Above the brows the template has no fiducial: the thin-plate spline extrapolates there, and it
continues the brows' motion with its own gradient, so that a brow raise or a frown carries the
forehead's rim further than the brows themselves (the default cohort's fits: 4-12 mm off the
skin's true motion in the top 5% of the template's rows, against a brow motion of 5-6.5 mm).
Where the skin shows no texture there (a mesh scan's flat vertex colours), the refinement has
nothing to correct it with.

A take's rim is therefore placed as the neutral's, moved by the 2D affine map that takes the
neutral's *still points* (:data:`STILL_POINTS`: the eye corners and the nose, which no viseme or
expression moves much) onto the take's; ``share`` of the spline's own motion of the rim is kept
on top. The rim's template points become extra fiducials of the take's spline
(:func:`anchored_fiducials`), so that between the brows and the rim the spline interpolates.
The neutral itself is fitted as before.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError, require_numbers
from scan2morph.tol import N_IBUG

#: iBUG numbers (1-based) of the still points: nose bridge and tip, nostril wings, subnasale,
#: outer and inner eye corners.
STILL_POINTS = (28, 31, 32, 34, 36, 37, 40, 43, 46)
#: The brows (iBUG 18-27): the rim is the template's outline above their mean height.
BROWS = tuple(range(18, 28))


@dataclass(frozen=True)
class Rim:
    """How a take's forehead rim follows its neutral's.

    Attributes
    ----------
    neutral_landmarks : (68, 2) float
        The neutral's iBUG-68 landmarks, px in the neutral's image.
    neutral_set : str
        The neutral's fiducial set (its own spline, :func:`~scan2morph.template.fit_map`).
    share : float
        Share of the take's own spline motion the rim keeps, in [0, 1]: 0 moves it with the
        still points alone, 1 is the plain spline (the paper's fit).
    """

    neutral_landmarks: np.ndarray
    neutral_set: str = "closed"
    share: float = 0.5

    def __post_init__(self) -> None:
        require_numbers("Rim", {"share": self.share})
        if not 0.0 <= self.share <= 1.0:
            raise InputError("Rim", f"share: expected a value in [0, 1], got {self.share}")


def rim_vertices(template) -> np.ndarray:
    """Indices (R,) of the template's outline vertices above the brows (y up is negative)."""
    brow_y = float(np.mean(template.ibug_xy[np.array(BROWS) - 1, 1]))
    outline = np.asarray(template.boundary)
    return outline[template.vertices[outline, 1] < brow_y]


def still_affine(neutral: np.ndarray, take: np.ndarray, source: str = "take") -> np.ndarray:
    """The least-squares 2D affine map from the neutral's still points to the take's.

    Parameters
    ----------
    neutral, take : (68, 2) float
        iBUG-68 landmarks, px.
    source : str
        ``subject/take`` for messages.

    Returns
    -------
    (3, 2) float64
        ``A`` with ``take ~ [1, x, y] @ A`` for neutral pixels ``(x, y)``.

    Raises
    ------
    InputError
        Landmarks not (68, 2) or not finite at the still points, or still points on one line.
    """
    idx = np.array(STILL_POINTS) - 1
    pts = []
    for name, lm in (("neutral landmarks", neutral), ("landmarks", take)):
        lm = np.asarray(lm, dtype=np.float64)
        if lm.shape != (N_IBUG, 2) or not np.isfinite(lm[idx]).all():
            raise InputError(
                source, f"{name}: expected ({N_IBUG}, 2) finite px at iBUG {list(STILL_POINTS)}"
            )
        pts.append(lm[idx])
    design = np.column_stack([np.ones(len(idx)), pts[0]])
    spread = np.linalg.svd(pts[0] - pts[0].mean(axis=0), compute_uv=False)
    if spread[1] <= 1e-3 * max(spread[0], 1e-300):
        raise InputError(source, "neutral landmarks: the eye corners and nose lie on one line")
    affine, *_ = np.linalg.lstsq(design, pts[1], rcond=None)
    return affine


def anchored_fiducials(
    template, src: np.ndarray, dst: np.ndarray, spline, neutral_spline, affine, share: float
) -> tuple[np.ndarray, np.ndarray]:
    """A take's fiducials with its rim's points added.

    Parameters
    ----------
    template : Template
        The base template.
    src, dst : (m, 2) float
        The take's fiducials: template coordinates and px.
    spline, neutral_spline : callable
        The take's and the neutral's plain splines: template coordinates (n, 2) -> px (n, 2).
    affine : (3, 2) float
        :func:`still_affine` of the neutral to the take.
    share : float
        :attr:`Rim.share`.

    Returns
    -------
    src, dst : (m + R, 2) float64
        With the R rim points of :func:`rim_vertices` after the take's own.
    """
    rim = template.vertices[rim_vertices(template)]
    still = np.column_stack([np.ones(len(rim)), neutral_spline(rim)]) @ affine
    target = still + share * (spline(rim) - still)
    return np.vstack([src, rim]), np.vstack([dst, target])
