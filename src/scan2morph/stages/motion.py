"""Motion: viseme motion vectors with the stencil mask and Laplacian smoothing, viseme models
(Yano & Harada 2009, sec. 4), and expression displacement fields (for the modal stage)."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from scan2morph.motion.model import (
    AlignedMesh,
    VisemeSmoothing,
    expression_displacements,
    viseme_motion,
)
from scan2morph.stages.failure import usable
from scan2morph.stages.part import Part, Run, Subject, need
from scan2morph.stages.quality import aligned_takes
from scan2morph.stages.refine import enabled as refine_enabled
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template
from scan2morph.template.regions import named_indices

#: Config sections this stage reads (``template`` for the subdivision level, ``refine`` for which
#: correspondence it compares).
SECTIONS = ("mask", "smoothing", "template", "quality", "refine")
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Motion parameters.

    Attributes
    ----------
    levels : int
        Template subdivisions.
    mask_paths : list of (str, str)
        Named start and goal points of the Dijkstra paths that seed the stencil mask.
    radius_mm : float
        Sphere radius of the mask, mm.
    w : float
        Laplacian smoothing weight.
    iterations : int
        Smoothing iterations.
    max_stretch : float
        Take vertices torn off the face beyond this edge stretch are invalid
        (``smoothing.max_stretch``; :mod:`scan2morph.motion.tear`).
    include_failed : bool
        Keep takes whose alignment failed its gate (``quality.include_failed_takes``).
    refined : bool
        Compare the refined meshes (``/takes/{take}/refine``) rather than the aligned fits
        (``refine.method`` other than ``none``).
    relief : float
        Share of the smoothing step taken off where the refinement measured a take's
        correspondence with confidence 1 (``smoothing.confidence_relief``; only with ``refined``).
    expression_iterations : int
        Smoothing iterations of the expression displacement fields
        (``smoothing.expression_iterations``).
    """

    levels: int
    mask_paths: list
    radius_mm: float
    w: float
    iterations: int
    max_stretch: float = np.inf
    include_failed: bool = False
    refined: bool = False
    relief: float = 0.0
    expression_iterations: int = 0

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``mask``, ``smoothing``, ``template``, ``quality`` and
        ``refine`` (none: the aligned fits are compared)."""
        mask, smoothing, template = config["mask"], config["smoothing"], config["template"]
        quality, refine = config["quality"], config.get("refine", {})
        return cls(
            int(template["subdivision_levels"]),
            list(mask["paths"]),
            mask["radius_mm"],
            smoothing["w"],
            smoothing["iterations"],
            float(smoothing["max_stretch"]),
            bool(quality["include_failed_takes"]),
            refine_enabled(refine),
            float(smoothing["confidence_relief"]),
            int(smoothing["expression_iterations"]),
        )


def aligned_mesh(
    data: Mapping[str, np.ndarray], take: str, source: str, refined: bool = False
) -> AlignedMesh:
    """A take's mesh in the neutral frame and its validity: the refined mesh (refine part, with
    the refinement's confidence; the consensus part's mesh where the takes' consensus moved it)
    or the aligned fit (fit and align parts)."""
    if refined:
        group = paths.refined(take, data)
        return AlignedMesh(
            need(data, group(take, "vertices"), source),
            need(data, group(take, "valid"), source),
            need(data, paths.refine(take, "confidence"), source),
        )
    return AlignedMesh(
        need(data, paths.align(take, "vertices"), source),
        need(data, paths.mesh(take, "valid"), source),
    )


def run(
    template: Template, subject: Subject, data: Mapping[str, np.ndarray], params: Params
) -> Part:
    """Motion of every viseme and displacement of every expression of one subject.

    Parameters
    ----------
    template, subject
        The base template and the subject (the contract of :mod:`scan2morph.stages`).
    data : mapping store path -> array
        The fit and align parts of every take (and their refine parts and the consensus part
        with ``params.refined``).
    params : Params

    Returns
    -------
    Part
        ``/mask/*``, ``/neutral/*``, ``/visemes/{take}/motion_raw|motion|model`` and
        ``/expressions/{take}/displacement`` (mm) of every take whose alignment passed its gate
        (``/takes/{take}/align/ok``; all with ``include_failed``) and was not left out of the
        subject (:mod:`scan2morph.stages.failure`). The later stages model the takes this stage
        kept.

    Raises
    ------
    InputError
        The neutral was left out (:func:`scan2morph.stages.failure.usable`): no subject.
    """
    fine = subdivide_template(template, params.levels)
    subject = usable(subject, data)
    others = [t for t in subject.kinds if t != subject.neutral]
    subject = subject.keep(aligned_takes(data, others, params.include_failed))
    name = subject.name
    ref = params.refined
    neutral = aligned_mesh(data, subject.neutral, name, ref)
    smoothing = VisemeSmoothing(
        params.radius_mm, params.w, params.iterations, params.max_stretch, params.relief
    )
    out = viseme_motion(
        neutral,
        {t: aligned_mesh(data, t, name, ref) for t in subject.visemes},
        fine.faces,
        named_indices(fine, params.mask_paths, "mask.paths"),
        smoothing,
        name,
    )
    out |= expression_displacements(
        neutral,
        {t: aligned_mesh(data, t, name, ref) for t in subject.expressions},
        fine.faces,
        name,
        params.max_stretch,
        params.w,
        params.expression_iterations,
        params.relief,
    )
    suppressed = out[paths.mask("suppressed")]
    log.info("%s: %d of %d vertices suppressed", name, suppressed.sum(), len(suppressed))
    return Part(out)


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """The stage for a subject held in memory."""
    return run(run_.template, run_.subject, data, Params.from_config(run_.config)).datasets
