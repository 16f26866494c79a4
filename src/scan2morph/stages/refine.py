"""Refine: each take's correspondence to the neutral corrected by image correlation of the skin
(:mod:`scan2morph.refine`), then aligned as the take was: the meshes the motion stage compares.

``refine.method: flow`` (the default) runs it; ``none`` keeps the paper's template-fit
correspondence (the motion stage then reads the aligned fits, and this stage is not run).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from scan2morph.align import transform_points
from scan2morph.refine import RefineParams, grey, refine_points
from scan2morph.stages.fit import fiducial_set
from scan2morph.stages.part import Part, Run, need
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template
from scan2morph.template.sample import fit_map, sample_mesh

#: Config sections this stage reads (``template`` for the subdivision level and sampling rules).
SECTIONS = ("refine", "template")
#: The last iBUG number of the jaw line (1-17: outline points, not skin points).
JAW_LINE = 17
#: ``refine.method`` values: image-correlation refinement, or the template fit as it is.
METHODS = ("flow", "none")
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Refinement parameters.

    Attributes
    ----------
    method : str
        One of :data:`METHODS`.
    levels : int
        Template subdivisions.
    min_weight, max_slope_deg : float
        The fit's sampling rules (``template.sample_min_weight``, ``template.max_slope_deg``).
    template : dict
        The config section ``template`` (its ``fiducials``: each take kind's fiducial set, the
        soft constraints).
    min_confident_share : float
        A take whose share of confidently measured vertices is below this keeps its template
        fit (``refine.min_confident_share``), with a warning.
    flow : RefineParams
        Everything else of the section ``refine``.
    """

    method: str
    levels: int
    min_weight: float
    max_slope_deg: float | None
    template: dict
    min_confident_share: float
    flow: RefineParams

    @classmethod
    def from_config(cls, refine: Mapping, template: Mapping) -> Params:
        """From the config sections ``refine`` and ``template``."""
        names = {f.name for f in fields(RefineParams)}
        return cls(
            str(refine["method"]),
            int(template["subdivision_levels"]),
            template["sample_min_weight"],
            template["max_slope_deg"],
            dict(template),
            float(refine.get("min_confident_share", 0.0)),
            RefineParams(**{k: v for k, v in refine.items() if k in names}),
        )


def enabled(refine: Mapping) -> bool:
    """Whether the config section ``refine`` asks for the refinement."""
    return refine.get("method", "none") != "none"


def sample_points(
    data: Mapping[str, np.ndarray],
    take: str,
    points: np.ndarray,
    faces: np.ndarray,
    params: Params,
    source: str,
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
    params : Params
        The fit's sampling rules (``min_weight``, ``max_slope_deg``).
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    vertices : (V, 3) float64
        mm in the neutral frame (the take's alignment applied); NaN where invalid.
    ok : (V,) bool
        Valid vertices; the fit's invalid vertices (folds, no data) stay invalid.
    """
    valid = np.asarray(need(data, paths.mesh(take, "valid"), source), dtype=bool)
    vertices, ok = sample_mesh(
        need(data, paths.range_image(take, "xyz"), source),
        points,
        faces,
        source,
        params.min_weight,
        params.max_slope_deg,
        exclude=np.flatnonzero(~valid),
    )
    transform = need(data, paths.align(take, "transform"), source)
    return transform_points(transform, vertices), ok


def run(
    template: Template,
    take: str,
    kind: str,
    neutral: str,
    data: Mapping[str, np.ndarray],
    params: Params,
    source: str,
) -> Part:
    """Refine one take's correspondence to the neutral.

    Parameters
    ----------
    template : Template
        The base template.
    take, kind, neutral : str
        The take, its kind and the subject's neutral take (the neutral is its own reference:
        its refined mesh is its aligned fit).
    data : mapping store path -> array
        The repair, fit and align parts of the take and the repair and fit parts of the neutral.
    params : Params
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    Part
        ``refine/vertices`` (V, 3) mm in the neutral frame (NaN where invalid), ``refine/valid``
        (V,), ``refine/points2d`` (V, 2) px in the take's image and ``refine/confidence`` (V,) (0
        where the fit was kept);
        the ``refine`` group's attributes hold the median correction (px), the share of
        vertices with a confident measurement, whether the refinement was ``used`` and, when not,
        the ``problem``.
    """
    aligned = need(data, paths.align(take, "vertices"), source)
    valid = np.asarray(need(data, paths.mesh(take, "valid"), source), dtype=bool)
    points = np.asarray(need(data, paths.mesh(take, "points2d"), source), dtype=np.float64)
    if take == neutral:
        out = {
            "vertices": aligned,
            "valid": valid,
            "points2d": points,
            "confidence": np.ones(len(valid)),
        }
        return Part({paths.refine(take, k): v for k, v in out.items()})
    fine = subdivide_template(template, params.levels)
    sets = {t: fiducial_set(params.template, k) for t, k in ((neutral, "neutral"), (take, kind))}
    maps = [
        fit_map(template, need(data, paths.landmarks(t), source), sets[t], source)
        for t in (neutral, take)
    ]
    numbers, base = template.fiducial_set(sets[take], source)
    # the jaw-line points (iBUG 1-17) sit on the face's outline, not on fixed skin points: they
    # are no constraint on where the skin went
    anchors = base[numbers > JAW_LINE]
    refined, report = refine_points(
        fine.vertices,
        fine.faces,
        *maps,
        grey(need(data, paths.range_image(neutral, "color"), source)),
        grey(need(data, paths.range_image(take, "color"), source)),
        anchors,
        params.flow,
    )
    problem = ""
    if report["confident_share"] < params.min_confident_share:
        # the two images do not share the skin's texture (another light, paint, camera or
        # modality): the measurement is not to be trusted, so the take keeps its fit
        problem = (
            f"only {100 * report['confident_share']:.0f}% of the face correlates with the "
            f"neutral's texture (refine.min_confident_share "
            f"{100 * params.min_confident_share:.0f}%): the template fit is kept"
        )
        log.warning("%s: refinement not used: %s", source, problem)
        refined = points
        # the points are the fit's: nothing was measured at them (the motion stage smooths
        # them as it smooths a fit's)
        report["confidence"] = np.zeros(len(points))
    vertices, ok = sample_points(data, take, refined, fine.faces, params, source)
    attrs = {
        "method": params.method,
        "used": not problem,
        "problem": problem,
        "median_correction_px": report["median_correction_px"],
        "confident_share": report["confident_share"],
        "valid_share": float(ok.mean()),
    }
    log.info("%s: refined %s", take, attrs)
    return Part(
        {
            paths.refine(take, "vertices"): vertices,
            paths.refine(take, "valid"): ok,
            paths.refine(take, "points2d"): refined,
            paths.refine(take, "confidence"): report["confidence"],
        },
        attrs={paths.refine_group(take): attrs},
    )


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """Every take of a subject held in memory (nothing when ``refine.method`` is ``none``)."""
    if not enabled(run_.config["refine"]):
        return {}
    params = Params.from_config(run_.config["refine"], run_.config["template"])
    neutral = run_.subject.neutral
    out = {}
    for take, kind in run_.subject.kinds.items():
        source = run_.subject.source(take)
        out |= run(run_.template, take, kind, neutral, data, params, source).datasets
    return out
