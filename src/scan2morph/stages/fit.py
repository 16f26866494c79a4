"""Fit: the template warped to a take's fiducials by a thin-plate spline, subdivided, and
sampled from its range image (Yano & Harada 2009, sec. 3.1): meshes in correspondence."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from scan2morph.align.noise import smoothing_gain
from scan2morph.errors import InputError
from scan2morph.scan import DEFAULT_DEPTH_REPAIR
from scan2morph.stages.part import Part, Run, Take, need
from scan2morph.store import paths
from scan2morph.store.warnings import landmark_source
from scan2morph.template import FitRules, Template, fit_take, subdivide_template
from scan2morph.template.rim import Rim

#: Config section this stage reads.
SECTIONS = ("template",)
#: Fiducial set of a take whose kind ``template.fiducials`` does not name.
DEFAULT_FIDUCIALS = "closed"
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Fit parameters.

    Attributes
    ----------
    fiducials : mapping take kind -> str
        Each take kind's fiducial set (``template.fiducials``: ``closed``, ``open`` or
        ``open_corners``, ``template.mesh.FIDUCIAL_SETS``); a kind not named gets
        :data:`DEFAULT_FIDUCIALS`.
    rules : FitRules
        Subdivisions (``template.subdivision_levels``), validity and fold limits
        (``min_valid_fraction``, ``max_fold_fraction``) and sampling rules
        (``sample_min_weight``, ``max_slope_deg``).
    rim_share : float
        Share of a take's own spline motion its forehead rim keeps (``template.rim_share``;
        :mod:`scan2morph.template.rim`): 0 places it from the neutral's by the eyes and nose,
        1 is the plain spline.
    depth_smooth_sigma_px : float
        The smoothing of a depth camera's noise at repair (``repair.depth_smooth_sigma_px``),
        px: a depth camera's take gets its ``mesh/noise_gain`` from it.
    """

    fiducials: Mapping[str, str]
    rules: FitRules
    rim_share: float = 0.5
    depth_smooth_sigma_px: float = 0.0

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's section ``template``."""
        section = config["template"]
        rules = FitRules(
            int(section["subdivision_levels"]),
            section["min_valid_fraction"],
            section["max_fold_fraction"],
            section["sample_min_weight"],
            section["max_slope_deg"],
        )
        repair = {**DEFAULT_DEPTH_REPAIR, **config.get("repair", {})}
        return cls(
            dict(section["fiducials"]),
            rules,
            float(section["rim_share"]),
            float(repair["depth_smooth_sigma_px"]),
        )

    def fiducial_set(self, kind: str) -> str:
        """The fiducial set of a take of ``kind``."""
        return self.fiducials.get(kind, DEFAULT_FIDUCIALS)

    def rim(self, take: Take) -> Rim | None:
        """How ``take``'s forehead rim follows its neutral's (its ``data`` holds the neutral's
        landmarks); None for the neutral itself, a take without one, or a share of 1."""
        if take.take == take.neutral or not take.neutral or self.rim_share >= 1.0:
            return None
        landmarks = need(take.data, paths.landmarks(take.neutral), take.source)
        return Rim(landmarks, self.fiducial_set("neutral"), self.rim_share)


def template_part(template: Template, params: Params) -> Part:
    """The ``/template`` group: faces, canonical 2D vertices and fiducials of the subdivided
    template (``params.rules.levels`` subdivisions).

    Fiducials are every iBUG point that is a template vertex (named ``ibugNN``, 1-based as in
    iBUG) followed by the named template points (``eye_r_outer``, ``forehead_centre``, ...).
    """
    fine = subdivide_template(template, params.rules.levels)
    numbers = np.flatnonzero(fine.ibug_vertex >= 0) + 1
    names = [f"ibug{n:02d}" for n in numbers] + list(fine.named)
    indices = np.concatenate([fine.ibug_vertex[numbers - 1], list(fine.named.values())])
    return Part(
        {
            paths.template("faces"): np.asarray(fine.faces, dtype=np.int64),
            paths.template("vertices2d"): np.asarray(fine.vertices, dtype=np.float64),
            paths.template("fiducials/names"): np.asarray(names, dtype=object),
            paths.template("fiducials/indices"): indices.astype(np.int64),
        }
    )


def run(template: Template, take: Take, params: Params) -> Part:
    """Fit the template to one take.

    Parameters
    ----------
    template : Template
        The base template.
    take : Take
        Its ``kind`` (the fiducial set), ``data`` (the repair part: ``range/xyz``,
        ``range/color``, ``landmarks``; for a take other than the neutral the neutral's
        ``landmarks`` too) and ``attrs`` (the take group's attributes so far, kept
        with the fit's added).
    params : Params

    Returns
    -------
    Part
        ``mesh/vertices`` (V, 3) mm (NaN where invalid), ``mesh/uv`` (V, 2), ``mesh/valid`` (V,),
        ``mesh/points2d`` (V, 2) px, and for a depth camera's take whose noise the repair
        smoothed ``mesh/noise_gain`` (:func:`~scan2morph.align.noise.smoothing_gain`: how many
        times its noise exceeds what its roughness reads); ``files`` holds ``faces`` (F, 3) and ``texture`` (the
        colour image) for the take's OBJ.
    """
    name, data, source = take.take, take.data, take.source
    fiducials = params.fiducial_set(take.kind)
    rim = params.rim(take)
    share = 1.0 if rim is None else rim.share
    try:
        mesh = fit_take(
            template,
            need(data, paths.landmarks(name), source),
            need(data, paths.range_image(name, "xyz"), source),
            fiducial_set=fiducials,
            rules=params.rules,
            source=source,
            rim=rim,
        )
    except InputError as exc:  # detected landmarks refused: say so, and how to give others
        detected = landmark_source(data, name)
        if "detected" not in detected:
            raise
        what = (
            "its landmarks were detected, not given"
            if detected == "detected"
            else f"its landmarks were {detected} (the jawline detected, the others given)"
        )
        raise InputError(
            exc.source,
            f"{exc.problem} ({what}: correct them in landmarks/{name}.pts, or {name}.xyz for a "
            "mesh take, of the subject's results and give that file in the sheet's landmarks "
            "column)",
        ) from None
    log.info(
        "%s: %d vertices, %.1f%% valid, %d folded triangles",
        name,
        len(mesh["valid"]),
        100 * mesh["valid"].mean(),
        mesh["n_folded"],
    )
    datasets = {paths.mesh(name, k): mesh[k] for k in ("vertices", "uv", "valid", "points2d")}
    sigma = params.depth_smooth_sigma_px
    if take.modality == "rgbd" and sigma > 0:  # the roughness reads its smoothed noise low
        gain = smoothing_gain(mesh["vertices"], mesh["valid"], mesh["points2d"], sigma)
        datasets[paths.mesh(name, "noise_gain")] = np.float64(gain)
    return Part(
        datasets,
        attrs={
            paths.take(name): dict(take.attrs)
            | {"fiducial_set": fiducials, "n_folded": mesh["n_folded"], "rim_share": share}
        },
        files={"faces": mesh["faces"], "texture": data.get(paths.range_image(name, "color"))},
    )


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """The template group and every take's fit, for a subject held in memory."""
    params = Params.from_config(run_.config)
    out = template_part(run_.template, params).datasets
    for take in run_.subject.kinds:
        out |= run(run_.template, Take.of(run_.subject, take, data=data), params).datasets
    return out
