"""Landmarks: the 68 iBUG points a take's template fit uses, clicked or detected.

A take whose landmark file gives all 68 points keeps them (``source`` ``clicked``). A take
without a landmark file has them detected on its repaired grid (:mod:`scan2morph.landmarks`:
``detected``); a 51-point file (iBUG-68 without the jawline) keeps its points and gets the
jawline detected (``clicked+detected jawline``). Detected points carry the detector's per-point
confidence, its name and version, and are checked as clicked ones are at ingest (a plausible,
frontal, right-handed face). A detected take other than the neutral then takes its stable points
(nose bridge, eye corners) from the neutral's, carried over by a rigid alignment of the two
scans (:func:`scan2morph.align.carry.carry_stable`), so that they agree across the subject's
takes, and its other points are followed from the neutral's by the skin's texture
(:func:`scan2morph.align.carry.track_points` with the refinement's image correlation,
:func:`scan2morph.refine.flow.measure_flow`) where the correlation is confident and lands near
the detection: the take's landmarks then move with its skin relative to the neutral's instead
of scattering by the detector's error. A detection whose confidence is low is *doubtful*: the take is
still used, with a warning at the top of the report and in ``accuracy.json``, and its mouth is
placed on the lips' colour edge (:func:`scan2morph.landmarks.fit_lips`), its brows on the
eyebrows' dark bands (:func:`scan2morph.landmarks.fit_brows`) and its chin, with the jawline, on
the face's outline below the mouth (:func:`scan2morph.landmarks.fit_chin`) before the second
pass.

Besides its part the stage writes the points as an iBUG ``.pts`` file (``files["pts"]``) and
lifted onto the take's surface (``files["xyz"]``,
:func:`~scan2morph.stages.landmark_files.written_points`: a mesh take's landmark
file, the pipeline's render being no image a user has; its given points as given), which a user
can correct and give back in the sheet's ``landmarks`` column.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from scan2morph.align.carry import carry_points, carry_stable, track_points
from scan2morph.errors import InputError
from scan2morph.io import check_face, check_handedness
from scan2morph.io.landmarks import complete
from scan2morph.refine import RefineParams, grey
from scan2morph.refine.flow import measure_flow
from scan2morph.stages import fit as fit_stage
from scan2morph.stages.landmark_files import written_points
from scan2morph.stages.part import Part, Run, Take, need
from scan2morph.stages.take_mesh import grids_turn
from scan2morph.store import paths
from scan2morph.template import FitRules, fit_folds

#: Config sections this stage reads (``template``: whether the fit would fold a detection).
SECTIONS = ("landmarks", "template")
#: ``source`` of a take's landmarks.
CLICKED, DETECTED, JAWLINE_DETECTED = "clicked", "detected", "clicked+detected jawline"
#: The image correlation that tracks a take's points from the neutral: the refinement's default
#: high-pass, noise, consistency and correlation tests.
FLOW = RefineParams()
#: A detected take whose points would fold its template fit moves the first of these shares of
#: the way to its neutral's points carried rigidly into it that folds no more (:func:`unfold`):
#: all the way where it can (the refinement then measures the mouth's motion from the neutral's
#: place; on the real head's stereo smile 0.547 of the motion against 1.315 with a quarter of
#: the way, benchmarks/bench_real_user.py), less where the neutral's closed inner lips cannot
#: serve a take fitted with them open.
UNFOLD_STEPS = (1.0, 0.75, 0.5, 0.25)


@dataclass(frozen=True)
class Params:
    """The landmarks stage's parameters (config section ``landmarks``).

    Attributes
    ----------
    min_confidence : float
        A detection whose median confidence over the points it placed falls below this is
        doubtful (a warning), in [0, 1].
    carry_stable : bool
        Whether a detected take's stable points are carried over from its neutral.
    stable_points : tuple of int
        iBUG numbers (1-based) of the points that do not move with the mouth.
    track : bool
        Whether a detected take's other points are followed from its neutral by image
        correlation (needs ``carry_stable``'s alignment).
    min_track_confidence : float
        A point is tracked when the correlation's confidence there is at least this, in [0, 1].
    max_track_px : float
        ... and the tracked position lies within this of the detected one, px.
    track_weight : float
        A tracked point's place: this share of the tracked position, the rest the detected one,
        in [0, 1] (1: the neutral's point as tracked; the neutral's own detection error then
        passes whole to the take, the take's is averaged out; 1: see ``turned_view_deg``).
    turned_view_deg : float or None
        A doubtful detection turned more than this (degrees) goes the whole way; None: never.
    unfold : bool
        Whether a detected take whose points would fold its template fit (so that the fit
        would leave it out) is moved towards its neutral's points carried rigidly
        (:func:`unfold`).
    lips_from_colour : bool
        Whether a doubtful detection's mouth is placed on the lips' colour edge
        (:func:`scan2morph.landmarks.fit_lips`).
    brows_from_colour : bool
        Whether a doubtful detection's brows are placed on the eyebrows' dark bands
        (:func:`scan2morph.landmarks.fit_brows`).
    chin_from_shape : bool
        Whether a doubtful detection's chin (and the jawline with it) is placed on the face's
        outline below the mouth (:func:`scan2morph.landmarks.fit_chin`).
    fit : scan2morph.stages.fit.Params or None
        The fit's parameters the fold test follows (config section ``template``: its fiducial
        sets, rim share, subdivisions and fold limit); None: no test (also with ``unfold`` or
        ``carry_stable`` off).
    """

    min_confidence: float = 0.5
    carry_stable: bool = True
    stable_points: tuple[int, ...] = (28, 37, 40, 43, 46)
    track: bool = True
    min_track_confidence: float = 0.3
    max_track_px: float = 6.0
    track_weight: float = 0.5
    turned_view_deg: float | None = None
    unfold: bool = True
    lips_from_colour: bool = True
    brows_from_colour: bool = True
    chin_from_shape: bool = True
    fit: fit_stage.Params | None = None

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        section = dict(config.get("landmarks") or {})
        turned = section.get("turned_view_deg", cls.turned_view_deg)
        return cls(
            min_confidence=float(section.get("min_confidence", cls.min_confidence)),
            carry_stable=bool(section.get("carry_stable", cls.carry_stable)),
            stable_points=tuple(int(n) for n in section.get("stable_points", cls.stable_points)),
            track=bool(section.get("track", cls.track)),
            min_track_confidence=float(
                section.get("min_track_confidence", cls.min_track_confidence)
            ),
            max_track_px=float(section.get("max_track_px", cls.max_track_px)),
            track_weight=float(section.get("track_weight", cls.track_weight)),
            turned_view_deg=None if turned is None else float(turned),
            unfold=bool(section.get("unfold", cls.unfold)),
            lips_from_colour=bool(section.get("lips_from_colour", cls.lips_from_colour)),
            brows_from_colour=bool(section.get("brows_from_colour", cls.brows_from_colour)),
            chin_from_shape=bool(section.get("chin_from_shape", cls.chin_from_shape)),
            fit=_fold_rules(config, section),
        )


def _fold_rules(config: Mapping, section: Mapping) -> fit_stage.Params | None:
    """The fit's parameters the fold test reads (the fiducial sets, the rim's share, the
    subdivisions and the fold limit; the sampling rules left at their defaults, so that changing
    them re-runs no landmarks stage), or None when no test is made: without ``template`` in the
    config, ``unfold`` or ``carry_stable`` off (the rigid carry needs its alignment)."""
    if "template" not in config or not section.get("unfold", True):
        return None
    if not section.get("carry_stable", True):
        return None
    fit = fit_stage.Params.from_config(config)
    rules = FitRules(fit.rules.levels, max_fold_fraction=fit.rules.max_fold_fraction)
    return replace(fit, rules=rules)


@dataclass(frozen=True)
class Landmarks:
    """A take's landmarks as the stage settles them.

    Attributes
    ----------
    points : (68, 2) float64
        0-based pixels on the take's grid.
    source : str
        :data:`CLICKED`, :data:`DETECTED` or :data:`JAWLINE_DETECTED`.
    confidence : (68,) float64 or None
        The detector's confidence per point; None when no point was detected with one (all
        clicked, or a 51-point file's jawline, which is placed on the clicked points).
    detector, version : str
        The detector's name and version (empty when all are clicked).
    """

    points: np.ndarray
    source: str
    confidence: np.ndarray | None = None
    detector: str = ""
    version: str = ""

    def doubtful(self, min_confidence: float) -> str:
        """Why the detection is doubtful (``""`` when it is not or nothing was detected)."""
        if self.confidence is None:
            return ""
        median = float(np.median(self.confidence))
        if median >= min_confidence:
            return ""
        return (
            f"the detected landmarks are doubtful: median confidence {median:.2f} below "
            f"{min_confidence:g} (landmarks.min_confidence); check them in the report and give "
            "corrected ones in the sheet's landmarks column"
        )


def settle(clicks: np.ndarray | None, color: np.ndarray, xyz: np.ndarray, source: str) -> Landmarks:
    """The take's 68 landmarks from its clicks, completed or replaced by detection.

    Parameters
    ----------
    clicks : (68, 2) float or None
        The landmark file's points (NaN rows for a 51-point file's jawline), None without one.
    color : (H, W, 3) uint8
        The take's colour image on its grid.
    xyz : (H, W, 3) float
        The take's repaired range image, mm, NaN where there is no surface.
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    Landmarks

    Raises
    ------
    InputError
        From the detector (no face, several faces, a face too small, a profile view); detected
        landmarks that fail the face checks of :func:`~scan2morph.io.check_face`.
    """
    if complete(clicks):
        return Landmarks(np.asarray(clicks, dtype=np.float64), CLICKED)
    from scan2morph.landmarks import DETECTOR, complete_jawline, detect

    if clicks is None:
        found = detect(color, xyz, source)
        out = Landmarks(found.points, DETECTED, found.confidence, found.detector, found.version)
    else:
        given = np.isfinite(clicks).all(axis=1)
        points = complete_jawline(clicks[given], color, xyz, source)
        points = np.where(given[:, None], clicks, points)
        out = Landmarks(points, JAWLINE_DETECTED, detector=DETECTOR)
    if out.source == DETECTED:
        hint = (
            "; these landmarks were detected: a detection this far off is wrong, give the take's "
            "landmarks in the sheet's landmarks column"
        )
        # the clicks' band (:data:`~scan2morph.io.take.EYE_SPAN_MM`) catches a detection far off
        # too (the real head's, 8 px off, puts them 68 mm apart against its annotation's 76 mm:
        # it goes on, flagged doubtful, and the report shows it for correction)
        try:
            check_face(xyz, out.points, source, f"{source} (detected landmarks)", hint)
        except InputError as exc:  # the take is left out: its points written for correction
            raise RefusedDetection(exc, out.points) from None
    else:  # the eye corners are clicked (a 51-point file): the clicks' band
        check_face(xyz, out.points, source, f"{source} (detected jawline)")
    return out


class RefusedDetection(InputError):
    """Detected landmarks that a face check refused (the take is left out), with the points,
    so that the user can correct them and give them back.

    Attributes
    ----------
    points : (68, 2) float64
        The detection, px on the take's grid.
    surface : (68, 3) float64 or None
        The same points on the take's measured surface, mm (:func:`written_points`), once
        :func:`run` has added them.
    """

    def __init__(self, refusal: InputError, points: np.ndarray):
        super().__init__(refusal.source, refusal.problem)
        self.points = np.asarray(points, dtype=np.float64)
        self.surface: np.ndarray | None = None


def run(template, take: Take, params: Params) -> Part:
    """Settle one take's landmarks.

    Parameters
    ----------
    template : Template or None
        The base template, for the fold test of a detected take's points (:func:`unfold`);
        None: no test.
    take : Take
        ``data``: the take's repair part (``range/xyz``, ``range/color``, ``clicks`` when
        given) and, for a take other than the neutral, the neutral's repair and landmarks parts
        (its stable points are carried over when the take's are detected).
    params : Params

    Returns
    -------
    Part
        ``landmarks`` (68, 2) px, ``landmark_source``, ``landmark_detector`` and
        ``landmark_doubtful`` (:func:`~scan2morph.store.paths.landmark_info`);
        ``landmark_confidence`` (68,) when any point was detected; ``landmark_detected`` (68, 2)
        px, the detector's points before its lips', brows' and chin's steps and the second pass
        (:func:`second_pass`); the take group's ``nose_depth_mm``
        (:func:`~scan2morph.io.check_handedness`) and, for a doubtful detection placed on the
        lips' colour edge (``params.lips_from_colour``), ``landmarks_lips_moved_px``, and
        with its brows on the eyebrows (``params.brows_from_colour``),
        ``landmarks_brows_moved_px``, and with its chin on the face's outline
        (``params.chin_from_shape``), ``landmarks_chin_moved_px``;
        ``files["pts"]`` the points for the ``.pts`` file, ``files["xyz"]`` (68, 3) mm the
        same points on the take's measured surface
        (:func:`~scan2morph.stages.landmark_files.written_points`: a mesh take's lie
        on the mesh, its given points as given), in its frame.
    """
    t, data = take.take, take.data
    xyz = np.asarray(need(data, paths.range_image(t, "xyz"), take.source), dtype=np.float64)
    color = need(data, paths.range_image(t, "color"), take.source)
    try:
        found = settle(data.get(paths.clicks(t)), color, xyz, take.source)
    except RefusedDetection as exc:
        exc.surface = written_points(xyz, take, exc.points)
        raise
    attrs, detected = {}, None
    if params.carry_stable and found.source == DETECTED and take.take != take.neutral:
        detected = found.points
    found, attrs = features_placed(found, (xyz, color), params)
    if detected is not None:
        found, carried = second_pass(found, take, (xyz, color), params, template)
        attrs |= carried
    doubtful = [found.doubtful(params.min_confidence)]
    if attrs.get("landmarks_unfolded"):
        doubtful.append(
            "the detected landmarks would make the template fit leave the take out (its "
            "triangles fold, or a point falls outside the image): moved "
            f"{attrs['landmarks_unfolded']:.0%} of the way to the neutral's, carried rigidly "
            "into the take; check them in the report"
        )
    datasets = {
        paths.landmarks(t): found.points,
        paths.landmark_info(t, "source"): found.source,
        paths.landmark_info(t, "detector"): f"{found.detector} {found.version}".strip(),
        paths.landmark_info(t, "doubtful"): "; ".join(filter(None, doubtful)),
    }
    if found.confidence is not None:
        datasets[paths.landmark_confidence(t)] = found.confidence
    if detected is not None:
        datasets[paths.landmark_detected(t)] = detected
    nose_depth = check_handedness(xyz, found.points, take.source)
    return Part(
        datasets,
        attrs={paths.take(t): attrs | {"nose_depth_mm": nose_depth}},
        files={"pts": found.points, "xyz": written_points(xyz, take, found.points)},
    )


def features_placed(
    found: Landmarks, grids: tuple[np.ndarray, np.ndarray], params: Params
) -> tuple[Landmarks, dict]:
    """A doubtful detection (``params.min_confidence``) with its mouth on the lips' colour edge
    (:func:`scan2morph.landmarks.fit_lips`, with ``params.lips_from_colour``), its brows on
    the eyebrows' dark bands (:func:`scan2morph.landmarks.fit_brows`, with
    ``params.brows_from_colour``) and its chin on the face's outline below the mouth
    (:func:`scan2morph.landmarks.fit_chin`, with ``params.chin_from_shape``); other detections
    as they are.

    Parameters
    ----------
    found : Landmarks
    grids : tuple of ndarray
        The take's ``xyz`` (H, W, 3) mm and ``color`` (H, W, 3) image.
    params : Params

    Returns
    -------
    found : Landmarks
    attrs : dict
        How far the features moved (median over their points, the chin's own move; px):
        ``landmarks_lips_moved_px``, ``landmarks_brows_moved_px``, ``landmarks_chin_moved_px``,
        for each step taken.
    """
    if not found.doubtful(params.min_confidence):
        return found, {}
    from scan2morph.landmarks import fit_brows, fit_chin, fit_lips

    xyz, color = (np.asarray(g) for g in grids)
    attrs = {}
    steps = (  # the chin's midline runs through the lips' midpoints: after the lips
        ("lips", params.lips_from_colour, fit_lips, color),
        ("brows", params.brows_from_colour, fit_brows, color),
        ("chin", params.chin_from_shape, fit_chin, xyz),
    )
    for name, wanted, fit, grid in steps:
        if wanted:
            placed = fit(grid, found.points)
            found = replace(found, points=placed.points)
            attrs[f"landmarks_{name}_moved_px"] = placed.moved_px
    return found, attrs


def second_pass(
    found: Landmarks,
    take: Take,
    grids: tuple[np.ndarray, np.ndarray],
    params: Params,
    template=None,
) -> tuple[Landmarks, dict]:
    """A detected take's landmarks against its neutral's: the stable points carried over, the
    others tracked by image correlation where it is confident (``params.track``), and, where
    the points would fold the take's template fit, moved towards the neutral's (:func:`unfold`,
    with ``template`` and ``params.unfold``).

    A tracked point goes ``params.track_weight`` of the way from the detection, when it lands
    within ``params.max_track_px`` of it. When the neutral's landmarks were given (clicked: no
    confidence), it goes the whole way, however far: the detector's error is then not in the
    neutral's points, so the take follows the user's points through the skin instead of
    keeping that error in its motion (the real head, a clicked neutral and a detected smile:
    0.49 of the skin's motion in error, 0.085 this way; both detected 0.090). So it does for a
    doubtful detection seen turned from the neutral (:func:`_reach`).

    Parameters
    ----------
    found : Landmarks
        The take's detected landmarks.
    take : Take
        ``data`` holds the neutral's repair and landmarks parts.
    grids : tuple of ((H, W, 3) float, (H, W, 3) uint8)
        The take's repaired range image (mm) and colour image.
    params : Params
    template : Template, optional
        The base template (None: no fold test).

    Returns
    -------
    found : Landmarks
        With the carried and tracked points in place; a tracked point's confidence is the
        neutral's and the take's weighted as its position is (it inherits the neutral's error
        in that share).
    attrs : dict
        ``landmarks_carried_px`` (the stable points' shifts, px), ``landmarks_view_turn_deg``
        (the take's camera from the neutral's, degrees: :func:`_view_turn`), ``landmarks_tracked``
        (how many points were tracked) and, when the points were unfolded,
        ``landmarks_unfolded`` (the share of the way to the neutral's, :func:`unfold`).
    """
    xyz, color = grids
    data, neutral = take.data, take.neutral
    neutral_xyz = np.asarray(
        need(data, paths.range_image(neutral, "xyz"), take.source), dtype=np.float64
    )
    neutral_points = need(data, paths.landmarks(neutral), take.source)
    carried = carry_stable(
        xyz, found.points, neutral_xyz, neutral_points, params.stable_points, take.source
    )
    attrs: dict = {
        "landmarks_carried_px": [float(v) for v in carried.shift_px],
        "landmarks_view_turn_deg": _view_turn(carried, xyz, neutral_xyz),
    }
    points, confidence = carried.points, found.confidence
    neutral_conf = data.get(paths.landmark_confidence(neutral))  # clicked: none, i.e. sure
    neutral_conf = np.ones(len(points)) if neutral_conf is None else np.asarray(neutral_conf)
    neutral_conf = np.nan_to_num(neutral_conf, nan=1.0)
    if params.track:
        neutral_color = need(data, paths.range_image(neutral, "color"), take.source)
        tracked = track_points(
            (xyz, grey(color)),
            (neutral_xyz, grey(neutral_color)),
            neutral_points,
            carried.transform,
            partial(
                measure_flow,
                sigma=FLOW.high_pass_px,
                noise=FLOW.noise_grey,
                max_fb_px=FLOW.max_fb_px,
                min_zncc=FLOW.min_zncc,
                level=FLOW.flow_level,
                match_gain=True,
            ),
            take.source,
        )
        reach, w = _reach(found, take, attrs["landmarks_view_turn_deg"], params)
        use = (tracked.confidence >= params.min_track_confidence) & (
            np.linalg.norm(tracked.points - found.points, axis=1) <= reach
        )
        use[np.asarray(params.stable_points) - 1] = False  # carried already
        points = np.where(use[:, None], w * tracked.points + (1 - w) * points, points)
        confidence = np.where(use, w * neutral_conf + (1 - w) * confidence, confidence)
        attrs["landmarks_tracked"] = int(use.sum())
    if template is not None and params.unfold and params.fit is not None:
        rigid = partial(
            carry_points, xyz, neutral_xyz, neutral_points, carried.transform, take.source
        )
        moved, share = unfold(template, take, points, rigid, xyz.shape[1::-1], params.fit)
        if share > 0:  # not NaN: no share unfolds them, and the fit says why
            attrs["landmarks_unfolded"] = share
            # a moved point inherits the neutral's error in that share, as a tracked one does
            went = np.any(moved != points, axis=1)
            confidence = np.where(went, share * neutral_conf + (1 - share) * confidence, confidence)
            points = moved
    return replace(found, points=points, confidence=confidence), attrs


def _reach(found: Landmarks, take: Take, turn: float, params: Params) -> tuple[float, float]:
    """How far from its detection a tracked point may land (px) and the share of the way it
    goes: the whole way from any distance beside a clicked neutral, or for a doubtful detection
    (``params.min_confidence``) whose camera stood more than ``params.turned_view_deg`` (``turn``,
    degrees; None: never) from the neutral's: a detector's errors on one face differ between
    views from two places (docs/landmarks.md, "The second pass")."""
    given = paths.landmark_confidence(take.neutral) not in take.data  # the neutral's clicked
    limit = params.turned_view_deg
    if given or (limit is not None and turn > limit and found.doubtful(params.min_confidence)):
        return np.inf, 1.0
    return params.max_track_px, params.track_weight


def _view_turn(carried, xyz: np.ndarray, neutral_xyz: np.ndarray) -> float:
    """How far the take's camera stood from the neutral's once aligned by ``carried``, degrees
    at the face (:func:`~scan2morph.stages.take_mesh.grids_turn`); NaN when
    fewer than 3 stable points were carried (the transform is no measure of the view then)."""
    if np.count_nonzero(carried.carried) < 3:
        return float("nan")
    return grids_turn(carried.transform, xyz, neutral_xyz)


def unfold(template, take: Take, points, rigid, size, fit: fit_stage.Params) -> tuple:
    """A detected take's points moved towards its neutral's until its template fit folds no
    more.

    A detection several px off (a face unlike the detector's training faces) can fold the
    thin-plate spline of the fit, which then leaves the take out; the clicked run of the same
    scans keeps it. The neutral's points carried rigidly into the take fold no more than the
    neutral's own fit (a rigid motion of the face; the mouth's motion is left to the
    refinement), so each point goes the largest share of :data:`UNFOLD_STEPS` of the way to its
    carried place with which the fit (:func:`~scan2morph.template.fit_folds`, the fit stage's
    rules) no longer folds.

    Parameters
    ----------
    template : Template
        The base template.
    take : Take
        Its kind (the fiducial set) and ``data`` (the neutral's landmarks, for the rim).
    points : (68, 2) float
        The take's points after the second pass, px.
    rigid : callable
        ``() -> (68, 2)`` px: the neutral's points carried rigidly into the take
        (:func:`~scan2morph.align.carry.carry_points`; NaN: the point stays), called only when
        the points fold.
    size : (width, height)
        The take's grid, px.
    fit : scan2morph.stages.fit.Params

    Returns
    -------
    points : (68, 2) float64
        As given when they do not fold or no share unfolds them.
    share : float
        The share taken; 0.0 when they did not fold, NaN when none of the steps unfolds them
        (the fit then leaves the take out, saying why).
    """
    folds = partial(
        fit_folds,
        template,
        image_size=size,
        fiducial_set=fit.fiducial_set(take.kind),
        rules=fit.rules,
        source=take.source,
        rim=fit.rim(take),
    )
    if not folds(points):
        return points, 0.0
    carried = rigid()
    found = np.isfinite(carried).all(axis=1)[:, None]
    if not found.any():  # nothing to go towards
        return points, float("nan")
    for share in UNFOLD_STEPS:
        trial = np.where(found, (1.0 - share) * points + share * carried, points)
        if not folds(trial):
            return trial, share
    return points, float("nan")


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """Every take of a subject (:class:`~scan2morph.stages.part.Run`)."""
    params = Params.from_config(run_.config)
    out: dict[str, np.ndarray] = {}
    neutral = run_.subject.neutral
    for t in [neutral, *(t for t in run_.subject.kinds if t != neutral)]:
        take = Take.of(run_.subject, t, data={**data, **out})  # the neutral's settled first
        out |= run(run_.template, take, params).datasets
    return out


__all__ = [
    "CLICKED",
    "DETECTED",
    "JAWLINE_DETECTED",
    "Landmarks",
    "Params",
    "features_placed",
    "run",
    "second_pass",
    "settle",
    "unfold",
]
