"""Report: one self-contained HTML page per subject (:mod:`scan2morph.report.html`)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from scan2morph.report import report_figures, stage_timings, write_subject_report

#: Config section this stage reads.
SECTIONS = ("report",)


def run(
    out: str | Path,
    store: str | Path,
    figures: Sequence[str],
    captions: Sequence[str],
    accuracy: Sequence[str],
    timings: Mapping,
    takes: Sequence[str],
    settings: Mapping,
    glb: str | Path | None = None,
) -> None:
    """Write a subject's report.

    Parameters
    ----------
    out, store : str or Path
        ``results/{subject}/report.html`` and the subject's store.
    figures, captions : sequence of str
        The figure PNGs and the caption files (matched by stem).
    accuracy : sequence of str
        ``accuracy.json`` of a synthetic subject, or nothing.
    timings : mapping
        ``benchmarks`` (folder of Snakemake's benchmark files), ``subject`` and ``order`` (rule
        names in workflow order) for :func:`scan2morph.report.stage_timings`.
    takes : sequence of str
        The subject's takes in sheet order.
    settings : mapping
        The config section ``report``: ``coordinates`` (modal coordinates shown) and
        ``thumbnail_px``.
    glb : str or Path, optional
        ``results/{subject}/{subject}.glb``, shown in the page's 3D viewer.
    """
    write_subject_report(
        out,
        store,
        figures=report_figures(figures, captions),
        accuracy=json.loads(Path(accuracy[0]).read_text()) if accuracy else None,
        timings=stage_timings(timings["benchmarks"], timings["subject"], timings["order"]),
        takes=takes,
        n_coordinates=settings["coordinates"],
        thumbnail_px=settings["thumbnail_px"],
        glb=glb,
    )
