"""Consensus: the takes refined by their shape registered to one another by their shared texture
(:mod:`scan2morph.refine.consensus`), before the motion stage compares them with the neutral."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError
from scan2morph.refine import grey, neutral_grid
from scan2morph.refine.consensus import MIN_TAKES, take_consensus
from scan2morph.stages import refine as refine_stage
from scan2morph.stages.failure import usable
from scan2morph.stages.part import Part, Run, Subject, need
from scan2morph.stages.quality import aligned_takes
from scan2morph.stages.take_mesh import sample_points, steep_skin
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template
from scan2morph.template.fit import fit_map

__all__ = ["MIN_TAKES", "Params", "apply", "members", "run"]

#: Config sections this stage reads (the refinement's, whose flow and sampling it repeats; the
#: quality gate's, which takes the models keep).
SECTIONS = ("refine", "template", "align", "quality")
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Consensus parameters (config section ``refine.consensus``).

    Attributes
    ----------
    use : bool
        Register the takes refined by their shape to one another (``refine.consensus.use``);
        only when the run refines (``refine.method`` other than ``none``).
    rounds : int
        Measure-and-move rounds (``refine.consensus.rounds``).
    refine : scan2morph.stages.refine.Params
        The refinement's: its flow's settings, the neutral's fiducials, the sampling rules and
        ``min_confident_share`` (a take that shares its texture with the others' on less of the
        template is left out).
    include_failed : bool
        Takes whose alignment failed its gate take part too (``quality.include_failed_takes``,
        as the motion stage models them).
    """

    use: bool
    rounds: int
    refine: refine_stage.Params
    include_failed: bool = False

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``refine`` (``refine.consensus``), ``template``, ``align``
        and ``quality``."""
        section = dict(config["refine"].get("consensus", {}))
        use = bool(section.get("use", True)) and refine_stage.enabled(config["refine"])
        rounds = section.get("rounds", 2)
        if isinstance(rounds, bool) or not isinstance(rounds, int | np.integer) or rounds < 1:
            raise InputError(
                "config", f"refine.consensus.rounds: expected an integer >= 1, got {rounds!r}"
            )
        include_failed = bool(config.get("quality", {}).get("include_failed_takes", False))
        return cls(use, int(rounds), refine_stage.Params.from_config(config), include_failed)


def members(subject: Subject, data: Mapping) -> list[str]:
    """The subject's takes (not its neutral) that its refinement refined by the surface's shape:
    their refine group's ``shape_used`` (a mapping under
    :func:`~scan2morph.store.paths.refine_group` in ``data``; a take without one is not)."""
    others = [t for t in subject.kinds if t != subject.neutral]
    return [t for t, by_shape in refine_stage.shape_verdicts(data, others).items() if by_shape]


def run(
    template: Template, subject: Subject, data: Mapping[str, np.ndarray], params: Params
) -> Part:
    """The consensus of one subject's takes refined by their shape.

    Parameters
    ----------
    template, subject
        The base template and the subject (the contract of :mod:`scan2morph.stages`).
    data : mapping store path -> array
        The repair, fit, align and refine parts of the takes, the neutral's landmarks part, and
        each take's refine group attributes (a mapping under
        :func:`~scan2morph.store.paths.refine_group`).
    params : Params

    Returns
    -------
    Part
        For each take registered: ``/takes/{take}/consensus/points2d`` (V, 2) px in its image,
        ``correction`` (V, 2) px (the move from its refined points), ``vertices`` (V, 3) mm in
        the neutral frame (NaN where invalid) and ``valid`` (V,), with the move's
        ``confident_share`` and ``median_correction_px`` in the group's attributes; the
        attributes of ``/consensus``: ``used``, ``problem`` (why not, ``""`` when used),
        ``takes`` (those registered) and ``left_out`` (members whose texture the others' shared
        on less than ``refine.min_confident_share`` of the template, with that share).
        Members are the takes refined by their shape whose alignment passed its gate (all of
        them with ``quality.include_failed_takes``), as the motion stage models them.
    """
    subject = usable(subject, data)
    takes = members(subject, data)
    if params.use:
        takes = aligned_takes(data, takes, params.include_failed)
    problem = _problem(params, takes)
    if problem:
        return _unused(problem)
    rp = params.refine
    name, neutral = subject.name, subject.neutral
    fine = subdivide_template(template, rp.levels)
    landmarks = need(data, paths.landmarks(neutral), subject.source(neutral))
    neutral_map = fit_map(template, landmarks, rp.fit.fiducial_set("neutral"), name)
    grid = neutral_grid(fine.vertices, fine.faces, neutral_map, rp.flow.margin_px)
    before = {
        t: np.asarray(need(data, paths.refine(t, "points2d"), subject.source(t)), float)
        for t in takes
    }
    images = {t: grey(need(data, paths.range_image(t, "color"), subject.source(t))) for t in takes}
    moved, report = take_consensus(
        grid, fine.vertices, before, images, rp.flow, params.rounds, rp.min_confident_share
    )
    left_out = [[t, report[t]["confident_share"]] for t in takes if not report[t]["kept"]]
    if not moved:
        problem = (
            f"fewer than {MIN_TAKES} takes share their texture on refine.min_confident_share "
            f"of the template: {left_out}"
        )
        return _unused(problem, left_out)
    takes = list(moved)
    datasets, attrs = {}, {}
    for take in takes:
        # the refined points plus the correction, as a click-noise draw adds it to its own
        # (stages.motion_noise): the undisturbed draw gives these points bit for bit
        correction = moved[take] - before[take]
        points = before[take] + correction
        # a carried take's steep skin is left to its neighbours, as in its refinement
        steep = steep_skin(data, (take, subject.neutral), rp, subject.source(take))
        confidence = need(data, paths.refine(take, "confidence"), take) if steep else None
        vertices, ok = sample_points(
            data, take, points, fine.faces, rp, subject.source(take), confidence
        )
        datasets |= {
            paths.consensus(take, "points2d"): points,
            paths.consensus(take, "correction"): correction,
            paths.consensus(take, "vertices"): vertices,
            paths.consensus(take, "valid"): ok,
        }
        attrs[paths.consensus_group(take)] = {
            k: report[take][k] for k in ("confident_share", "median_correction_px")
        }
    log.info("%s: consensus of %s: %s", name, ", ".join(takes), report)
    attrs[paths.CONSENSUS] = {"used": True, "problem": "", "takes": takes, "left_out": left_out}
    return Part(datasets, attrs=attrs)


def _problem(params: Params, takes: list[str]) -> str:
    """Why no consensus is made of ``takes`` (``""``: it is)."""
    if not params.use:
        return "off (refine.consensus.use false, or refine.method none)"
    if len(takes) < MIN_TAKES:
        return (
            f"{len(takes)} take(s) refined by their shape (their texture does not correlate "
            f"with the neutral's) whose alignment passed its gate; a consensus needs at least "
            f"{MIN_TAKES}"
        )
    return ""


def _unused(problem: str, left_out=()) -> Part:
    """The part of a subject without a consensus: why not."""
    attrs = {"used": False, "problem": problem, "takes": [], "left_out": list(left_out)}
    return Part({}, attrs={paths.CONSENSUS: attrs})


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """The stage for a subject held in memory."""
    return run(run_.template, run_.subject, data, Params.from_config(run_.config)).datasets
