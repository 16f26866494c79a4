"""Align: each take rigidly onto the neutral, from six stable point pairs (Kabsch), then ICP on
the stable face (Yano & Harada 2009, sec. 3.2). The neutral's own transform is the identity."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from scan2morph.align import AlignMeshes, IcpParams, align_take, transform_points
from scan2morph.errors import InputError
from scan2morph.stages.part import Part, Run, Take, need
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template
from scan2morph.template.regions import icp_region, named_indices

#: Config sections this stage reads (``template`` for the subdivision level).
SECTIONS = ("align", "template")
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Alignment parameters.

    Attributes
    ----------
    levels : int
        Template subdivisions (the meshes' topology).
    point_pairs : list of str
        Named template points of the initial pose (``align.point_pairs``).
    icp_region : str
        The region ICP refines on (``align.icp_region``).
    grow_into : str
        The region whose still skin the ICP region grows into (``align.grow_into``: a region
        name of :func:`~scan2morph.template.regions.icp_region`, or ``none``).
    icp : IcpParams
        ICP's settings (``align.icp``).
    """

    levels: int
    point_pairs: list
    icp_region: str
    grow_into: str
    icp: IcpParams

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``align`` and ``template``."""
        align, template = config["align"], config["template"]
        return cls(
            int(template["subdivision_levels"]),
            list(align["point_pairs"]),
            align["icp_region"],
            align["grow_into"],
            icp_params(align),
        )


def icp_params(align: Mapping) -> IcpParams:
    """:class:`~scan2morph.align.IcpParams` of the config section ``align`` (its ``icp``); their
    own check's problem named by the config key."""
    try:
        return IcpParams(**align.get("icp", {}))
    except InputError as exc:
        raise InputError("config", f"align.icp: {exc.problem}") from None


def grow_indices(fine: Template, name: str) -> np.ndarray | None:
    """Vertex indices of the region named by ``align.grow_into``; None for ``none``."""
    return None if name == "none" else np.flatnonzero(icp_region(fine, name))


def run(template: Template, take: Take, params: Params) -> Part:
    """Align one take to the neutral.

    Parameters
    ----------
    template : Template
        The base template.
    take : Take
        Its ``neutral`` (the take itself: the identity) and ``data`` (the fit parts of both:
        ``mesh/vertices``, ``mesh/valid``, and ``mesh/noise_gain`` where a depth camera's
        smoothed noise reads low: the RMSE gate's expected RMSE is corrected by it).
    params : Params

    Returns
    -------
    Part
        ``align/transform`` (4, 4), scanner frame -> neutral frame, and ``align/vertices``
        (V, 3) mm, and ``align/ok``: the alignment passed its quality gate; the ``align``
        group's attributes hold ICP's fitness, inlier RMSE (mm), the point-to-plane RMSE of
        the kept stable region (``residual_rmse_mm``) and its share (``inlier_fraction``),
        the measured noise of the take's and the neutral's region (``noise_take_mm``,
        ``noise_neutral_mm``), the RMSE a right alignment leaves (``expected_rmse_mm``), the
        RMSE limit used (``rmse_limit_mm``, ``rmse_limit_kind`` relative | absolute), the
        robust kernel's final scale (``kernel_k_mm``), iterations, convergence, method, the
        ``recovery`` tried and the ``problems`` of a failed gate.
    """
    data, source, name, neutral = take.data, take.source, take.take, take.neutral
    src = need(data, paths.mesh(name, "vertices"), source)
    attrs, ok = {}, True
    if name == neutral:
        transform = np.eye(4)
    else:
        fine = subdivide_template(template, params.levels)
        meshes = AlignMeshes(
            src,
            need(data, paths.mesh(name, "valid"), source),
            need(data, paths.mesh(neutral, "vertices"), source),
            need(data, paths.mesh(neutral, "valid"), source),
            fine.faces,
            *(float(data.get(paths.mesh(t, "noise_gain"), 1.0)) for t in (name, neutral)),
        )
        result = align_take(
            meshes,
            named_indices(fine, params.point_pairs, "align.point_pairs"),
            np.flatnonzero(icp_region(fine, params.icp_region)),
            params.icp,
            source=source,
            grow_indices=grow_indices(fine, params.grow_into),
        )
        transform = result.transform
        ok = bool(result.ok)
        attrs = {
            paths.align_group(name): dict(
                fitness=result.fitness,
                inlier_rmse_mm=result.inlier_rmse,
                residual_rmse_mm=result.residual_rmse,
                inlier_fraction=result.inlier_fraction,
                noise_take_mm=result.noise_take,
                noise_neutral_mm=result.noise_neutral,
                expected_rmse_mm=result.expected_rmse,
                rmse_limit_mm=result.rmse_limit,
                rmse_limit_kind=result.rmse_limit_kind,
                kernel_k_mm=result.kernel_k,
                iterations=result.iterations,
                converged=result.converged,
                method=result.method,
                problems=list(result.problems),
                recovery=list(result.recovery),
            )
        }
        log.info("%s: %s", name, attrs[paths.align_group(name)])
        if not ok:
            log.warning(
                "%s: alignment failed its quality gate: %s", source, "; ".join(result.problems)
            )
    return Part(
        {
            paths.align(name, "transform"): transform,
            paths.align(name, "vertices"): transform_points(transform, src),
            paths.align(name, "ok"): np.bool_(ok),
        },
        attrs=attrs,
    )


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """Every take of a subject held in memory."""
    params = Params.from_config(run_.config)
    out = {}
    for take in run_.subject.kinds:
        out |= run(run_.template, Take.of(run_.subject, take, data=data), params).datasets
    return out
