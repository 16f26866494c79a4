"""Repair: spikes out, small holes filled (Yano & Harada 2009, sec. 3.1)."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from scan2morph.scan import repair_range
from scan2morph.stages.part import Part, Run, Take, need
from scan2morph.store import paths

if TYPE_CHECKING:  # a type only: the template (and scipy) stay unimported until used
    from scan2morph.template import Template

#: Config section this stage reads.
SECTIONS = ("repair",)
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Repair parameters.

    Attributes
    ----------
    settings : mapping
        The config section ``repair`` (:func:`scan2morph.scan.repair_range`'s settings).
    """

    settings: Mapping

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's section ``repair``."""
        return cls(dict(config["repair"]))


def run(template: Template | None, take: Take, params: Params) -> Part:
    """Repair one take's range image (an RGB-D take's as depth-camera data: flying pixels at
    depth edges dropped, depth noise smoothed).

    Parameters
    ----------
    template : Template or None
        Not used (the contract's shape).
    take : Take
        Its ``data`` (the ingest part: ``raw/xyz``, ``raw/color``, ``clicks`` when given) and ``attrs``
        (the take group's attributes so far, kept with the repair report added; ``modality``
        ``rgbd`` marks depth-camera data).
    params : Params

    Returns
    -------
    Part
        ``range/xyz`` (float32, mm), ``range/color``, ``range/spikes``, ``range/filled``,
        ``clicks`` (when given) and the ``camera/*`` provenance; ``files["report"]`` is the repair report
        (counts, holes filled and left).
    """
    name, data, source = take.take, take.data, take.source
    xyz, report = repair_range(
        need(data, paths.raw(name, "xyz"), source),
        dict(params.settings),
        source=source,
        depth_camera=take.modality == "rgbd",
    )
    filled, spikes = report.pop("filled"), report.pop("spikes")
    report.pop("flying", None)
    log.info("%s: %s", name, report)
    return Part(
        {
            paths.range_image(name, "xyz"): xyz.astype(np.float32),
            paths.range_image(name, "color"): need(data, paths.raw(name, "color"), source),
            paths.range_image(name, "spikes"): spikes,
            paths.range_image(name, "filled"): filled,
            **_clicks(data, name),
            **camera_datasets(data, name),
        },
        attrs={paths.take(name): dict(take.attrs) | {"repair": report}},
        files={"report": report},
    )


def _clicks(data: Mapping[str, np.ndarray], take: str) -> dict[str, np.ndarray]:
    """The take's clicked landmarks (and a mesh take's 3D points), passed on when its ingest
    part has them."""
    keys = (paths.clicks(take), paths.clicks_3d(take))
    return {key: data[key] for key in keys if key in data}


def camera_datasets(data: Mapping[str, np.ndarray], take: str) -> dict[str, np.ndarray]:
    """The take's ``camera/*`` provenance datasets that ``data`` holds (ingest writes them)."""
    names = ("modality", "model", "color_source", "K", "distortion", "pose", "size")
    return {
        paths.camera(take, n): data[paths.camera(take, n)]
        for n in names
        if paths.camera(take, n) in data
    }


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """Every take of a subject (:class:`~scan2morph.stages.part.Run`)."""
    params = Params.from_config(run_.config)
    out = {}
    for take in run_.subject.kinds:
        out |= run(run_.template, Take.of(run_.subject, take, data=data), params).datasets
    return out
