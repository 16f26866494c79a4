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
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template
from scan2morph.template.fit import fit_map

__all__ = ["MIN_TAKES", "Params", "apply", "members", "run"]

#: Config sections this stage reads (the refinement's, whose flow and sampling it repeats).
SECTIONS = ("refine", "template", "align")
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
        The refinement's: its flow's settings, the neutral's fiducials and the sampling rules.
    """

    use: bool
    rounds: int
    refine: refine_stage.Params

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``refine`` (``refine.consensus``), ``template`` and
        ``align``."""
        section = dict(config["refine"].get("consensus", {}))
        use = bool(section.get("use", True)) and refine_stage.enabled(config["refine"])
        rounds = section.get("rounds", 2)
        if isinstance(rounds, bool) or not isinstance(rounds, int | np.integer) or rounds < 1:
            raise InputError(
                "config", f"refine.consensus.rounds: expected an integer >= 1, got {rounds!r}"
            )
        return cls(use, int(rounds), refine_stage.Params.from_config(config))


def members(subject: Subject, data: Mapping) -> list[str]:
    """The subject's takes (not its neutral) that its refinement refined by the surface's shape:
    their refine group's ``shape_used`` (a mapping under
    :func:`~scan2morph.store.paths.refine_group` in ``data``; a take without one is not)."""
    out = []
    for take in subject.kinds:
        attrs = data.get(paths.refine_group(take))
        if take != subject.neutral and isinstance(attrs, Mapping):
            if bool(attrs.get("shape_used", False)):
                out.append(take)
    return out


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
        attributes of ``/consensus``: ``used``, ``problem`` (why not, ``""`` when used) and
        ``takes`` (those registered).
    """
    subject = usable(subject, data)
    takes = members(subject, data)
    problem = ""
    if not params.use:
        problem = "off (refine.consensus.use false, or refine.method none)"
    elif len(takes) < MIN_TAKES:
        problem = (
            f"{len(takes)} take(s) refined by their shape (their texture does not correlate "
            f"with the neutral's); a consensus needs at least {MIN_TAKES}"
        )
    if problem:
        return Part({}, attrs={paths.CONSENSUS: {"used": False, "problem": problem, "takes": []}})
    rp = params.refine
    name, neutral = subject.name, subject.neutral
    fine = subdivide_template(template, rp.levels)
    landmarks = need(data, paths.landmarks(neutral), subject.source(neutral))
    neutral_map = fit_map(template, landmarks, rp.fit.fiducial_set("neutral"), name)
    grid = neutral_grid(fine.vertices, fine.faces, neutral_map, rp.flow.margin_px)
    before = {t: np.asarray(data[paths.refine(t, "points2d")], dtype=np.float64) for t in takes}
    images = {t: grey(need(data, paths.range_image(t, "color"), subject.source(t))) for t in takes}
    moved, report = take_consensus(grid, fine.vertices, before, images, rp.flow, params.rounds)
    datasets, attrs = {}, {}
    for take in takes:
        correction = moved[take] - before[take]
        points = before[take] + correction
        vertices, ok = refine_stage.sample_points(
            data, take, points, fine.faces, rp, subject.source(take)
        )
        datasets |= {
            paths.consensus(take, "points2d"): points,
            paths.consensus(take, "correction"): correction,
            paths.consensus(take, "vertices"): vertices,
            paths.consensus(take, "valid"): ok,
        }
        attrs[paths.consensus_group(take)] = report[take]
    log.info("%s: consensus of %s: %s", name, ", ".join(takes), report)
    attrs[paths.CONSENSUS] = {"used": True, "problem": "", "takes": takes}
    return Part(datasets, attrs=attrs)


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """The stage for a subject held in memory."""
    return run(run_.template, run_.subject, data, Params.from_config(run_.config)).datasets
