"""Repair: spikes out, small holes filled (Yano & Harada 2009, sec. 3.1)."""

from __future__ import annotations

import logging
from collections.abc import Mapping

import numpy as np

from scan2morph.scan import repair_range
from scan2morph.stages.part import Part, Run, need
from scan2morph.store import paths

#: Config section this stage reads.
SECTIONS = ("repair",)
log = logging.getLogger("scan2morph")


def run(
    take: str, data: Mapping[str, np.ndarray], attrs: Mapping, settings: Mapping, source: str
) -> Part:
    """Repair one take's range image (an RGB-D take's as depth-camera data: flying pixels at
    depth edges dropped, depth noise smoothed).

    Parameters
    ----------
    take : str
    data : mapping store path -> array
        The take's ingest part (``raw/xyz``, ``raw/color``, ``clicks`` when given).
    attrs : mapping
        The take group's attributes so far (kept, with the repair report added); ``modality``
        ``rgbd`` marks depth-camera data.
    settings : mapping
        The config section ``repair``.
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    Part
        ``range/xyz`` (float32, mm), ``range/color``, ``range/spikes``, ``range/filled``,
        ``clicks`` (when given) and the ``camera/*`` provenance; ``files["report"]`` is the repair report (counts, holes filled and left).
    """
    xyz, report = repair_range(
        need(data, paths.raw(take, "xyz"), source),
        dict(settings),
        source=source,
        depth_camera=_modality(data, attrs, take) == "rgbd",
    )
    filled, spikes = report.pop("filled"), report.pop("spikes")
    report.pop("flying", None)
    log.info("%s: %s", take, report)
    return Part(
        {
            paths.range_image(take, "xyz"): xyz.astype(np.float32),
            paths.range_image(take, "color"): need(data, paths.raw(take, "color"), source),
            paths.range_image(take, "spikes"): spikes,
            paths.range_image(take, "filled"): filled,
            **{k: data[k] for k in (paths.clicks(take),) if k in data},
            **camera_datasets(data, take),
        },
        attrs={paths.take(take): dict(attrs) | {"repair": report}},
        files={"report": report},
    )


def _modality(data: Mapping[str, np.ndarray], attrs: Mapping, take: str) -> str:
    """The take's modality: the take group's attribute, else the ingest part's dataset."""
    if "modality" in attrs:
        return str(attrs["modality"])
    value = data.get(paths.camera(take, "modality"), "range")
    return value.decode() if isinstance(value, bytes) else str(value)


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
    out = {}
    for take in run_.subject.kinds:
        out |= run(take, data, {}, run_.config["repair"], run_.subject.source(take)).datasets
    return out
