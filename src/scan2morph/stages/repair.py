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
    """Repair one take's range image.

    Parameters
    ----------
    take : str
    data : mapping store path -> array
        The take's ingest part (``raw/xyz``, ``raw/color``, ``landmarks``).
    attrs : mapping
        The take group's attributes so far (kept, with the repair report added).
    settings : mapping
        The config section ``repair``.
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    Part
        ``range/xyz`` (float32, mm), ``range/color``, ``range/spikes``, ``range/filled``,
        ``landmarks``; ``files["report"]`` is the repair report (counts, holes filled and left).
    """
    xyz, report = repair_range(
        need(data, paths.raw(take, "xyz"), source), dict(settings), source=source
    )
    filled, spikes = report.pop("filled"), report.pop("spikes")
    log.info("%s: %s", take, report)
    return Part(
        {
            paths.range_image(take, "xyz"): xyz.astype(np.float32),
            paths.range_image(take, "color"): need(data, paths.raw(take, "color"), source),
            paths.range_image(take, "spikes"): spikes,
            paths.range_image(take, "filled"): filled,
            paths.landmarks(take): need(data, paths.landmarks(take), source),
        },
        attrs={paths.take(take): dict(attrs) | {"repair": report}},
        files={"report": report},
    )


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """Every take of a subject (:class:`~scan2morph.stages.part.Run`)."""
    out = {}
    for take in run_.subject.kinds:
        out |= run(take, data, {}, run_.config["repair"], run_.subject.source(take)).datasets
    return out
