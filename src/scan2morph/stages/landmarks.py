"""Landmarks: the 68 iBUG points a take's template fit uses, clicked or detected.

A take whose landmark file gives all 68 points keeps them (``source`` ``clicked``). A take
without a landmark file has them detected on its repaired grid (:mod:`scan2morph.landmarks`:
``detected``); a 51-point file (iBUG-68 without the jawline) keeps its points and gets the
jawline detected (``clicked+detected jawline``). Detected points carry the detector's per-point
confidence, its name and version, and are checked as clicked ones are at ingest (a plausible,
frontal, right-handed face). A detected take other than the neutral then takes its stable points
(nose bridge, eye corners) from the neutral's, carried over by a rigid alignment of the two
scans (:func:`scan2morph.align.carry.carry_stable`), so that they agree across the subject's
takes. A detection whose confidence is low is *doubtful*: the take is
still used, with a warning at the top of the report and in ``accuracy.json``.

Besides its part the stage writes the points as an iBUG ``.pts`` file (``files["pts"]``) that a
user can correct and give back in the sheet's ``landmarks`` column.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from scan2morph.align.carry import carry_stable
from scan2morph.io import check_face, check_handedness
from scan2morph.io.landmarks import complete
from scan2morph.stages.part import Part, Run, Take, need
from scan2morph.store import paths

#: Config sections this stage reads.
SECTIONS = ("landmarks",)
#: ``source`` of a take's landmarks.
CLICKED, DETECTED, JAWLINE_DETECTED = "clicked", "detected", "clicked+detected jawline"


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
    """

    min_confidence: float = 0.5
    carry_stable: bool = True
    stable_points: tuple[int, ...] = (28, 37, 40, 43, 46)

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        section = dict(config.get("landmarks") or {})
        return cls(
            min_confidence=float(section.get("min_confidence", cls.min_confidence)),
            carry_stable=bool(section.get("carry_stable", cls.carry_stable)),
            stable_points=tuple(int(n) for n in section.get("stable_points", cls.stable_points)),
        )


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
    check_face(xyz, out.points, source, f"{source} (detected landmarks)")
    return out


def run(template, take: Take, params: Params) -> Part:
    """Settle one take's landmarks.

    Parameters
    ----------
    template : Template or None
        Unused (the per-take stages' one shape).
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
        px, the detector's points before the stable ones were carried over; the take group's ``nose_depth_mm`` (:func:`~scan2morph.io.check_handedness`);
        ``files["pts"]`` the points for the ``.pts`` file.
    """
    t, data = take.take, take.data
    xyz = np.asarray(need(data, paths.range_image(t, "xyz"), take.source), dtype=np.float64)
    color = need(data, paths.range_image(t, "color"), take.source)
    found = settle(data.get(paths.clicks(t)), color, xyz, take.source)
    attrs, detected = {}, None
    if params.carry_stable and found.source == DETECTED and take.take != take.neutral:
        neutral_xyz = need(data, paths.range_image(take.neutral, "xyz"), take.source)
        neutral_points = need(data, paths.landmarks(take.neutral), take.source)
        carried = carry_stable(
            xyz, found.points, neutral_xyz, neutral_points, params.stable_points, take.source
        )
        detected = found.points
        found = replace(found, points=carried.points)
        attrs["landmarks_carried_px"] = [float(v) for v in carried.shift_px]
    datasets = {
        paths.landmarks(t): found.points,
        paths.landmark_info(t, "source"): found.source,
        paths.landmark_info(t, "detector"): f"{found.detector} {found.version}".strip(),
        paths.landmark_info(t, "doubtful"): found.doubtful(params.min_confidence),
    }
    if found.confidence is not None:
        datasets[paths.landmark_confidence(t)] = found.confidence
    if detected is not None:
        datasets[paths.landmark_detected(t)] = detected
    nose_depth = check_handedness(xyz, found.points, take.source)
    return Part(
        datasets,
        attrs={paths.take(t): attrs | {"nose_depth_mm": nose_depth}},
        files={"pts": found.points},
    )


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """Every take of a subject (:class:`~scan2morph.stages.part.Run`)."""
    params = Params.from_config(run_.config)
    out: dict[str, np.ndarray] = {}
    neutral = run_.subject.neutral
    for t in [neutral, *(t for t in run_.subject.kinds if t != neutral)]:
        take = Take.of(run_.subject, t, data={**data, **out})  # the neutral's settled first
        out |= run(run_.template, take, params).datasets
    return out


__all__ = ["CLICKED", "DETECTED", "JAWLINE_DETECTED", "Landmarks", "Params", "run", "settle"]
