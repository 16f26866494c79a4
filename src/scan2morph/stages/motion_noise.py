"""Motion noise: the click precision measured from the subject's own takes, and the
click-noise error bar of each viseme's motion (refits with perturbed landmarks; no ground truth).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from scan2morph.align import transform_points
from scan2morph.motion.uncertainty import DrawRecipe, subject_motion_noise
from scan2morph.refine.memo import sharing
from scan2morph.stages import fit as fit_stage
from scan2morph.stages import refine as refine_stage
from scan2morph.stages.part import Part, Run, Subject, Take, need
from scan2morph.stages.quality import modelled
from scan2morph.stages.refine import shape_verdicts
from scan2morph.stages.take_mesh import sample_points, steep_skin
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template

#: Config sections this stage reads (``refine`` and ``align``: the error bar of the refined
#: correspondence, whose jaw prior uses the alignment's ICP settings).
SECTIONS = ("motion_noise", "smoothing", "template", "refine", "align")
#: Columns of ``tables/motion_noise.tsv``: result key -> column name (the RMS values are over
#: the vertices outside the mask; dictionary: :data:`scan2morph.tables.MOTION_NOISE`).
COLUMNS = {
    "motion_rms_mm": "motion_rms_unmasked_mm",
    "rms_error_mm": "noise_rms_unmasked_mm",
    "relative": "noise_relative_unmasked",
    "failed_draws": "failed_draws",
}
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Motion-noise parameters.

    Attributes
    ----------
    noise : mapping
        The config section ``motion_noise`` (draws, seed, click noise).
    smoothing : mapping
        The config section ``smoothing`` (each draw's motion is smoothed as the motion stage's).
    fit : scan2morph.stages.fit.Params
        The fit's (each draw refits the takes).
    refine : scan2morph.stages.refine.Params or None
        The refinement's, when ``refine.method`` asks for it (each draw refines the visemes
        too); None otherwise.
    """

    noise: Mapping
    smoothing: Mapping
    fit: fit_stage.Params
    refine: refine_stage.Params | None = None

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``motion_noise``, ``smoothing``, ``template``, and
        ``refine`` and ``align`` when it refines."""
        refine = None
        if refine_stage.enabled(config.get("refine", {})):
            refine = refine_stage.Params.from_config(config)
        fit = fit_stage.Params.from_config(config)
        return cls(dict(config["motion_noise"]), dict(config["smoothing"]), fit, refine)


def _refiner(
    template: Template,
    subject: Subject,
    data,
    params: refine_stage.Params,
    by_shape: Mapping[str, bool] | None = None,
):
    """The refine stage as a function of a viseme's and the neutral's clicks (a click-noise
    draw): the take's fit to its clicks refined against the neutral seen through its clicks.
    ``by_shape``: take -> whether the pipeline refined it by the surface's shape (its texture
    did not correlate); a take it does not name takes its first draw's verdict. A take the
    takes' consensus moved (its ``correction`` in ``data``) moves each draw's refined points by
    that correction too, sampled as the consensus samples them."""
    neutral = subject.neutral
    by_shape = dict(by_shape or {})  # take -> its draws go to the shape straight away
    # the takes' consensus moved these takes' refined points (stages.consensus): each draw's
    # refined points move by the same correction, so the undisturbed clicks give the pipeline's
    moves = {t: data.get(paths.consensus(t, "correction")) for t in subject.visemes}
    moves = {t: m for t, m in moves.items() if m is not None}
    faces = subdivide_template(template, params.levels).faces if moves else None

    def refiner(take, mesh, take_landmarks, neutral_landmarks):
        source = subject.source(take)
        transform = need(data, paths.align(take, "transform"), source)
        draw = dict(data) | {
            paths.landmarks(take): take_landmarks,
            paths.landmarks(neutral): neutral_landmarks,
            paths.mesh(take, "valid"): mesh["valid"],
            paths.mesh(take, "points2d"): mesh["points2d"],
            paths.align(take, "vertices"): transform_points(transform, mesh["vertices"]),
        }
        # a take whose texture did not correlate (in the pipeline's refinement, else in its
        # first draw) is refined by the shape straight away (the same numbers; the texture
        # pass is a quarter of a texture-mismatched subject's draws)
        p = replace(params, texture_unmatched=True) if by_shape.get(take) else params
        part = refine_stage.run(template, Take.of(subject, take, data=draw), p)
        by_shape.setdefault(take, bool(part.attrs[paths.refine_group(take)]["shape_used"]))
        d = part.datasets
        vertices, valid = d[paths.refine(take, "vertices")], d[paths.refine(take, "valid")]
        confidence = d[paths.refine(take, "confidence")]
        if take in moves:  # as the consensus moved the take's own refinement
            points = d[paths.refine(take, "points2d")] + moves[take]
            steep = steep_skin(draw, (take, neutral), p, source)
            vertices, valid = sample_points(
                draw, take, points, faces, p, source, confidence if steep else None
            )
        return vertices, valid, confidence

    return refiner


def run(
    template: Template, subject: Subject, data: Mapping[str, np.ndarray], params: Params
) -> Part:
    """The error bar of one subject.

    Parameters
    ----------
    template, subject
        The base template and the subject (the contract of :mod:`scan2morph.stages`).
    data : mapping store path -> array
        The repair parts of the neutral and the visemes, their align parts and the motion
        part (the visemes it modelled, ``/mask``); when the run refines, each viseme's refine
        group attributes too (``paths.refine_group(take)`` -> mapping, :func:`~scan2morph.stages.refine.shape_verdicts`):
        a viseme whose texture the pipeline found not correlating (``shape_used``) is refined
        by the surface's shape straight away in every draw, one it refined by its texture
        tries the texture in every draw, and one without them takes its first draw's verdict;
        and the consensus part (``/takes/{take}/consensus/correction`` of the visemes the takes'
        consensus moved: each draw's refined points of such a viseme move by the same
        correction, :mod:`scan2morph.stages.consensus`).
    params : Params
        (With ``params.refine``, each draw refines the visemes too:
        ``motion_noise.refine_draws`` draws.)

    Returns
    -------
    Part
        ``/visemes/{take}/noise_rms_mm`` and ``/motion_noise/*``; ``files["table"]`` is the
        per-viseme table (``motion_rms_unmasked_mm``, ``noise_rms_unmasked_mm``,
        ``noise_relative_unmasked``, ``failed_draws``, ``click_noise_px_used``; written by
        :func:`scan2morph.tables.write_table` with :data:`scan2morph.tables.MOTION_NOISE`).
    """
    subject = modelled(subject, data)
    noise_cfg = params.noise
    fiducials = {t: params.fit.fiducial_set(k) for t, k in subject.kinds.items()}
    refiner = None
    if params.refine is not None:
        verdicts = shape_verdicts(data, subject.visemes)
        refiner = _refiner(template, subject, data, params.refine, verdicts)
    recipe = DrawRecipe(params.fit.rules, params.smoothing, refiner, params.fit.rim_share)
    # the draws' common work (the neutral's side, each take's) once
    with sharing() as counts:
        datasets, result, noise = subject_motion_noise(
            template, data, subject.neutral, subject.visemes, fiducials, recipe, noise_cfg,
            subject.name,
        )  # fmt: skip
    log.info("%s: work shared by the draws (step: [reused, computed]): %s", subject.name, counts)
    log.info("%s: click noise %s", subject.name, noise["note"])
    for take, name, r in noise["misclicks"]:
        log.warning(
            "%s/%s: landmark %d is %.1f px off the others (mis-click?)", subject.name, take, name, r
        )
    for take, r in result.items():
        if np.isfinite(r["relative"]):
            log.info("%s: click noise moves the motion by %.1f%%", take, 100 * r["relative"])
    attrs = {
        paths.MOTION_NOISE: {
            "draws": noise_cfg["refine_draws" if refiner else "draws"],
            "refined": refiner is not None,
            "seed": noise_cfg["seed"],
            "click_noise_source": noise["source"],
            "click_noise_note": noise["note"],
            "misclicks": [list(m) for m in noise["misclicks"]],
        }
    }
    rows = [{"take": t, **{c: r[k] for k, c in COLUMNS.items()}} for t, r in result.items()]
    table = pd.DataFrame(rows, columns=["take", *COLUMNS.values()])
    table["click_noise_px_used"] = noise["click_noise_px"]
    if not subject.visemes:
        attrs[paths.SKIPPED] = {"motion_noise": "no viseme takes: no click-noise error bar"}
    return Part(datasets, attrs=attrs, files={"table": table})


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """The stage for a subject held in memory."""
    return run(run_.template, run_.subject, data, Params.from_config(run_.config)).datasets
