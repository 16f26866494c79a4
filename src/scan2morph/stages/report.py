"""Report: one self-contained HTML page per subject (:mod:`scan2morph.report.html`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from scan2morph.report import ReportPage, report_figures, subject_report_html
from scan2morph.stages.part import Part, Subject
from scan2morph.template import Template

#: Config section this stage reads.
SECTIONS = ("report",)


@dataclass(frozen=True)
class Params:
    """Report parameters.

    Attributes
    ----------
    coordinates : int
        Modal coordinates (and frequencies) shown per expression (``report.coordinates``).
    thumbnail_px : int
        Width of the input thumbnails, px (``report.thumbnail_px``).
    """

    coordinates: int
    thumbnail_px: int

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's section ``report``."""
        section = config["report"]
        return cls(int(section["coordinates"]), int(section["thumbnail_px"]))


def run(template: Template | None, subject: Subject, data: Mapping, params: Params) -> Part:
    """A subject's report page.

    Parameters
    ----------
    template : Template or None
        Not used (the contract's shape).
    subject : Subject
        Its takes, in sheet order (the inputs section's order).
    data : mapping
        What the page shows, as the job read it: ``store`` (the path of
        ``results/{subject}/{subject}.h5``, read by the page itself), ``figures`` and
        ``captions`` (the figure PNGs and caption files, matched by stem), ``accuracy``
        (``accuracy.json``'s content, or None without ground truth), ``timings`` (rows of
        :func:`scan2morph.report.stage_timings`) and ``glb`` (``results/{subject}/{subject}.glb``
        for the 3D viewer, or None).
    params : Params

    Returns
    -------
    Part
        No datasets; ``files["html"]`` is the page's text (for
        :func:`scan2morph.report.html.write_html`).
    """
    page = ReportPage(
        figures=report_figures(data.get("figures", ()), data.get("captions", ())),
        accuracy=data.get("accuracy"),
        timings=data.get("timings", ()),
        takes=list(subject.kinds),
        n_coordinates=params.coordinates,
        thumbnail_px=params.thumbnail_px,
        glb=data.get("glb"),
    )
    html = subject_report_html(data["store"], page)
    return Part(files={"html": html})
