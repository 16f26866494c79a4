"""Fit: the template warped to a take's fiducials by a thin-plate spline, subdivided, and
sampled from its range image (Yano & Harada 2009, sec. 3.1): meshes in correspondence."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from scan2morph.stages.part import Part, Run, need
from scan2morph.store import paths
from scan2morph.template import Template, fit_options, fit_take, subdivide_template

#: Config section this stage reads.
SECTIONS = ("template",)
#: Fiducial set of a take whose kind ``template.fiducials`` does not name.
DEFAULT_FIDUCIALS = "closed"
log = logging.getLogger("scan2morph")


def fiducial_set(section: Mapping, kind: str) -> str:
    """The fiducial set of a take of ``kind`` under the config section ``template``."""
    return section["fiducials"].get(kind, DEFAULT_FIDUCIALS)


@dataclass(frozen=True)
class Params:
    """Fit parameters of one take.

    Attributes
    ----------
    fiducial_set : str
        ``closed``, ``open`` or ``open_corners`` (``template.mesh.FIDUCIAL_SETS``).
    options : dict
        :func:`scan2morph.template.fit_options` of the section (levels, validity and fold
        limits, sampling weight, depth-step rule).
    """

    fiducial_set: str
    options: dict

    @classmethod
    def from_config(cls, section: Mapping, kind: str) -> Params:
        """From the config section ``template`` and the take's kind."""
        return cls(fiducial_set(section, kind), fit_options(section))


def template_part(template: Template, section: Mapping) -> Part:
    """The ``/template`` group: faces, canonical 2D vertices and fiducials of the subdivided
    template (``template.subdivision_levels``).

    Fiducials are every iBUG point that is a template vertex (named ``ibugNN``, 1-based as in
    iBUG) followed by the named template points (``eye_r_outer``, ``forehead_centre``, ...).
    """
    fine = subdivide_template(template, int(section["subdivision_levels"]))
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


def run(
    template: Template,
    take: str,
    data: Mapping[str, np.ndarray],
    attrs: Mapping,
    params: Params,
    source: str,
) -> Part:
    """Fit the template to one take.

    Parameters
    ----------
    template : Template
        The base template.
    take : str
    data : mapping store path -> array
        The take's repair part (``range/xyz``, ``range/color``, ``landmarks``).
    attrs : mapping
        The take group's attributes so far (kept, with the fit's added).
    params : Params
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    Part
        ``mesh/vertices`` (V, 3) mm (NaN where invalid), ``mesh/uv`` (V, 2), ``mesh/valid`` (V,),
        ``mesh/points2d`` (V, 2) px; ``files`` holds ``faces`` (F, 3) and ``texture`` (the
        colour image) for the take's OBJ.
    """
    mesh = fit_take(
        template,
        need(data, paths.landmarks(take), source),
        need(data, paths.range_image(take, "xyz"), source),
        fiducial_set=params.fiducial_set,
        source=source,
        **params.options,
    )
    log.info(
        "%s: %d vertices, %.1f%% valid, %d folded triangles",
        take,
        len(mesh["valid"]),
        100 * mesh["valid"].mean(),
        mesh["n_folded"],
    )
    return Part(
        {paths.mesh(take, k): mesh[k] for k in ("vertices", "uv", "valid", "points2d")},
        attrs={
            paths.take(take): dict(attrs)
            | {"fiducial_set": params.fiducial_set, "n_folded": mesh["n_folded"]}
        },
        files={"faces": mesh["faces"], "texture": data.get(paths.range_image(take, "color"))},
    )


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """The template group and every take's fit, for a subject held in memory."""
    section = run_.config["template"]
    out = template_part(run_.template, section).datasets
    for take, kind in run_.subject.kinds.items():
        params = Params.from_config(section, kind)
        out |= run(run_.template, take, data, {}, params, run_.subject.source(take)).datasets
    return out
