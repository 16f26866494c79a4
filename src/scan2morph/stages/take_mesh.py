"""A take's mesh sampled at its template's pixels, in the neutral frame: what the refine stage,
the takes' consensus and the click-noise draws resample once they have moved a take's points.

A take whose detection, or its neutral's, is doubtful (:func:`carries_upper`) has its upper face
carried from the neutral in the refinement (:mod:`scan2morph.refine.carried`), and its template
may reach the head's sides, where a pixel is several mm of depth; a take seen from another
place than its neutral (:func:`view_turn`: the head turned between them) sees one side of the
face more obliquely than the neutral does, and the two fits place that skin mm apart. In both
(:func:`steep_skin`) a vertex on skin steeper than ``max_unmeasured_slope_deg`` (the refinement
measured nothing there) or ``max_measured_slope_deg`` (it did) is invalid, and the motion stage
fills its motion from its neighbours'. Every resampling of such a take applies the same limits.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scan2morph.align import transform_points, view_turn_deg
from scan2morph.geometry import finite_points
from scan2morph.scan.view import scanner_view
from scan2morph.stages.part import need
from scan2morph.store import paths
from scan2morph.store.warnings import landmark_source, text_value
from scan2morph.template.sample import sample_mesh

#: ``refine.carry_upper_face`` values (:mod:`scan2morph.refine.carried`): a doubtful detection of
#: the take or its neutral (``landmark_doubtful``), every detected take, every take, none.
CARRY_UPPER = ("doubtful", "detected", "all", "none")
#: A vertex is measured where the refinement's confidence is at least this.
MEASURED = 0.5


def carries_upper(data: Mapping[str, np.ndarray], takes: tuple[str, str], which: str) -> bool:
    """Whether a take's upper face is carried from its neutral.

    Parameters
    ----------
    data : mapping store path -> array
        Holds the take's and the neutral's landmarks parts.
    takes : (str, str)
        The take's and its neutral's names.
    which : str
        One of :data:`CARRY_UPPER`.
    """
    if which in ("all", "none"):
        return which == "all"
    if which == "detected":
        return landmark_source(data, takes[0]) == "detected"
    return any(text_value(data.get(paths.landmark_info(t, "doubtful"), "")) for t in takes)


def view_turn(data: Mapping[str, np.ndarray], takes: tuple[str, str], source: str) -> float:
    """How far a take's camera stood from its neutral's, as the face sees them once the take is
    aligned, degrees (:func:`~scan2morph.align.view_turn_deg`).

    Each camera is the one that took the take's grid, estimated from the grid itself
    (:func:`~scan2morph.scan.view.scanner_view`: range XYZ may come in any frame; a mesh take's
    grid is its virtual camera's); the face is the middle (median) of the neutral's points.

    Parameters
    ----------
    data : mapping store path -> array
        Holds the take's alignment and both takes' range images (their repair parts).
    takes : (str, str)
        The take's and its neutral's names.
    source : str
        ``subject/take``, for messages.
    """
    grids = [np.asarray(need(data, paths.range_image(t, "xyz"), source)) for t in takes]
    return grids_turn(need(data, paths.align(takes[0], "transform"), source), *grids)


def grids_turn(transform: np.ndarray, xyz: np.ndarray, neutral_xyz: np.ndarray) -> float:
    """:func:`view_turn` of a take aligned to its neutral by ``transform`` (4, 4), take ->
    neutral frame, from the two range images (H, W, 3) mm: each camera found from its grid, the
    face the middle of the neutral's, degrees."""
    cameras = [scanner_view(grid).centre for grid in (xyz, neutral_xyz)]
    return float(view_turn_deg(transform, *cameras, grid_middle(neutral_xyz)))


def grid_middle(xyz: np.ndarray) -> np.ndarray:
    """(3,) the median of a range image's (H, W, 3) points with data, mm: the face's middle,
    where :func:`view_turn` measures the turn."""
    return np.median(xyz[finite_points(xyz)], axis=0)


def steep_skin(data: Mapping[str, np.ndarray], takes: tuple[str, str], params, source: str) -> bool:
    """Whether a take's steep skin is left to its neighbours (module docstring): its upper face
    is carried (:func:`carries_upper`, ``params.carry_upper_face``) or it was seen from more than
    ``params.turned_view_deg`` (degrees; None: never) away from where its neutral was
    (:func:`view_turn`).

    ``params`` is a :class:`scan2morph.stages.refine.Params`; the other arguments are
    :func:`view_turn`'s."""
    if carries_upper(data, takes, params.carry_upper_face):
        return True
    limit = params.turned_view_deg
    return takes[0] != takes[1] and limit is not None and view_turn(data, takes, source) > limit


def sample_points(
    data: Mapping[str, np.ndarray],
    take: str,
    points: np.ndarray,
    faces: np.ndarray,
    params,
    source: str,
    confidence: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A take's mesh sampled from its range image at pixel positions, in the neutral frame.

    Parameters
    ----------
    data : mapping store path -> array
        The take's repair, fit and align parts.
    take : str
    points : (V, 2) float
        Pixel positions of the template's vertices in the take's image, px.
    faces : (F, 3) int
        The subdivided template's triangles.
    params : scan2morph.stages.refine.Params
        The fit's sampling rules (``min_weight``, ``max_slope_deg``) and the steep skin's
        limits (``max_unmeasured_slope_deg``, ``max_measured_slope_deg``, degrees; None: none).
    source : str
        ``subject/take``, for messages.
    confidence : (V,) float, optional
        The refinement's confidence at ``points``, for a take whose upper face is carried: a
        vertex on skin steeper than its limit (measured where at least :data:`MEASURED`) is
        invalid. None: the fit's rules alone.

    Returns
    -------
    vertices : (V, 3) float64
        mm in the neutral frame (the take's alignment applied); NaN where invalid.
    ok : (V,) bool
        Valid vertices; the fit's invalid vertices (folds, no data) stay invalid.
    """
    valid = np.asarray(need(data, paths.mesh(take, "valid"), source), dtype=bool)
    xyz = need(data, paths.range_image(take, "xyz"), source)

    def sample(max_slope_deg):
        rules = (params.min_weight, max_slope_deg)
        return sample_mesh(xyz, points, faces, source, *rules, exclude=np.flatnonzero(~valid))

    vertices, ok = sample(params.max_slope_deg)
    if confidence is not None:  # a pixel on steep skin is mm of depth: its neighbours serve
        measured = np.asarray(confidence) >= MEASURED
        limits = (params.max_unmeasured_slope_deg, params.max_measured_slope_deg)
        for limit, which in zip(limits, (~measured, measured), strict=True):
            if limit is not None:
                ok &= sample(limit)[1] | ~which
        vertices = np.where(ok[:, None], vertices, np.nan)
    transform = need(data, paths.align(take, "transform"), source)
    return transform_points(transform, vertices), ok


__all__ = [
    "CARRY_UPPER",
    "MEASURED",
    "carries_upper",
    "grid_middle",
    "grids_turn",
    "sample_points",
    "steep_skin",
    "view_turn",
]
