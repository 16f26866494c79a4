"""The per-subject report: one self-contained HTML page (``results/{subject}/report.html``).

The page embeds everything it shows (images as base64 ``data:`` URIs, inline CSS, the glTF and
the one script of the 3D viewer, :mod:`scan2morph.report.viewer`) so it opens from disk with no
server, and declares a Content-Security-Policy that forbids loading anything else (the viewer's
script is allowed by its hash). Sections: the warnings, the accuracy against ground truth
(synthetic subjects; it leads with the error of each viseme's motion and each expression's
displacement against the material motion of the skin, total, normal and tangential, the
method-ideal error as the second line), the subject's inputs (a thumbnail of each take's color
image), the 3D viewer of the subject's glTF, every figure with a one-line caption, the PCA
tables (Yano and Harada, Tables 1 and 2), the modal coordinates of the expressions, their
reconstruction error against the number of modes (total, normal and tangential parts, the
modes that reach the target error) and the displacement on the clamped outline, and
provenance (store attributes, input checksums, software versions, run time per stage).

The page comes from Jinja2 templates (package data in ``report/templates``: ``subject.html.j2``
the page, ``macros.html.j2`` its blocks, ``viewer.html.j2`` the 3D viewer, ``report.css``) with
autoescaping on, so every text is HTML-escaped. What each section shows is gathered by
:mod:`scan2morph.report.sections` (lists of blocks that ``macros.html.j2`` renders) and
:mod:`scan2morph.report.viewer`; this module puts the page together and writes it.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import jinja2
from markupsafe import Markup

from scan2morph.errors import InputError, writing
from scan2morph.report import sections, viewer
from scan2morph.report.accuracy import accuracy as accuracy_tables
from scan2morph.report.provenance import software_versions, store_provenance
from scan2morph.report.sections import ReportFigure
from scan2morph.store import open_store

#: Only embedded data and inline styles may load (a stray external reference is blocked and
#: reported by the browser instead of being fetched); :func:`csp` adds the viewer's script.
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"


def csp(script: str | None = None) -> str:
    """The page's Content-Security-Policy: :data:`CSP`, and with the viewer's inline ``script``
    that script alone (by hash) and the ``blob:``/``data:`` loads its glTF loader makes."""
    if script is None:
        return CSP
    return (
        f"default-src 'none'; {viewer.CSP_SOURCES}; style-src 'unsafe-inline'; "
        f"script-src {viewer.script_hash(script)}"
    )


@functools.lru_cache(maxsize=1)
def environment() -> jinja2.Environment:
    """The report templates (package data ``scan2morph/report/templates``), autoescaping on."""
    return jinja2.Environment(
        loader=jinja2.PackageLoader("scan2morph.report", "templates"),
        autoescape=True,
        trim_blocks=True,
        lstrip_blocks=True,
    )


def render_blocks(blocks: Sequence[Mapping]) -> str:
    """HTML of a section's blocks (``macros.html.j2``)."""
    return environment().get_template("macros.html.j2").module.blocks(list(blocks))


def _status_section(h5: h5py.File) -> str:
    """The HTML of the page's first section (:func:`scan2morph.report.sections.status` rendered)."""
    return render_blocks(sections.status(h5)).strip()


@dataclass(frozen=True)
class ReportPage:
    """What a subject's report page shows besides its store (:func:`subject_report_html`).

    Attributes
    ----------
    figures : sequence of ReportFigure
        PNG/JPEG files (stems ``{stage}_{name}``) with one-line captions, in report order.
    accuracy : mapping, optional
        The content of ``accuracy.json`` (``units``, ``summary``, ``takes``); None when the
        subject has no ground truth.
    timings : sequence of mapping
        Rows of :func:`~scan2morph.report.provenance.stage_timings`.
    versions : mapping, optional
        Software name -> version; default :func:`~scan2morph.report.provenance.software_versions`.
    takes : sequence of str, optional
        Take order of the inputs section (default: neutral, visemes, expressions, by id).
    n_coordinates : int
        Number of modal coordinates (and frequencies) shown per expression.
    thumbnail_px : int
        Width of the input thumbnails, pixels.
    glb : str or Path, optional
        ``results/{subject}/{subject}.glb``, shown in the 3D viewer (without it, or without
        three.js in ``three_dir``, the viewer section says why there is none).
    three_dir : str or Path
        The npm package ``three`` (default ``tools/viewer/node_modules/three``).
    """

    figures: Sequence[ReportFigure] = ()
    accuracy: Mapping | None = None
    timings: Sequence[Mapping[str, object]] = ()
    versions: Mapping[str, str] | None = None
    takes: Sequence[str] | None = None
    n_coordinates: int = 10
    thumbnail_px: int = 160
    glb: str | Path | None = None
    three_dir: str | Path = viewer.THREE_DIR


def subject_report_html(store_path: str | Path, page: ReportPage | None = None) -> str:
    """The report page of one subject.

    Parameters
    ----------
    store_path : str or Path
        ``results/{subject}/{subject}.h5`` (its major format version is checked).
    page : ReportPage, optional
        What the page shows besides the store (default: nothing more).

    Returns
    -------
    str
        The HTML document.

    Raises
    ------
    InputError
        Unreadable store, glTF or figure, a figure of an unsupported type, bad checksum attribute.
    """
    p = ReportPage() if page is None else page
    figures, accuracy, timings, takes, glb = p.figures, p.accuracy, p.timings, p.takes, p.glb
    n_coordinates, thumbnail_px, versions = p.n_coordinates, p.thumbnail_px, p.versions
    three_dir = p.three_dir
    if n_coordinates < 1 or thumbnail_px < 1:
        raise InputError("report", "n_coordinates and thumbnail_px: expected positive integers")
    versions = software_versions() if versions is None else versions
    with open_store(store_path) as h5:
        attrs, checksums = store_provenance(h5)
        subject = str(attrs.get("subject", Path(store_path).stem))
        order = sections.take_order(h5, takes)
        view, script = viewer.viewer_context(glb, h5, order, n_coordinates, three_dir)
        parts = [
            ("status", "Warnings and skipped stages", sections.status(h5)),
            ("accuracy", "Accuracy against ground truth", accuracy_tables(accuracy)),
            ("inputs", "Inputs", sections.inputs(h5, order, thumbnail_px)),
            ("viewer", "3D model (glTF viewer)", [{"kind": "viewer", "viewer": view}]),
            ("figures", "Figures", sections.figures(figures)),
            ("motion-noise", "Viseme motion: click-noise error", sections.motion_noise(h5)),
            ("pca", "PCA (Yano and Harada, Tables 1 and 2)", sections.pca(h5)),
            ("modal", "Modal coordinates", sections.modal(h5, n_coordinates)),
            ("provenance", "Provenance", sections.provenance(attrs, checksums, versions, timings)),
        ]
    lead = (
        f"{len(order)} takes; store format {attrs.get('format_version', '?')}, "
        f"scan2morph {attrs.get('scan2morph_version', '?')}; units: mm, angles in degrees."
    )
    return (
        environment()
        .get_template("subject.html.j2")
        .render(
            subject=subject,
            lead=lead,
            csp=csp(script),
            files=_files(subject, accuracy is not None),
            sections=[{"id": i, "title": t, "blocks": b} for i, t, b in parts],
            # the bundle refuses '</script' and '<!--': safe to embed as it is (and hashed as is)
            script=None if script is None else Markup(script),
        )
    )


def _files(subject: str, synthetic: bool) -> list[dict]:
    """Links to the products the page describes (relative: the page sits in
    ``results/{subject}/`` beside them)."""
    files = {
        f"{subject}.h5": "store (HDF5)",
        f"{subject}.glb": "model (glTF)",
        "meshes/": "meshes (OBJ)",
        "tables/": "tables (TSV)",
        "figures/": "figures (PNG)",
    }
    if synthetic:
        files["accuracy.json"] = "accuracy (JSON)"
    return [{"href": f, "what": what} for f, what in files.items()]


def write_subject_report(
    path: str | Path, store_path: str | Path, page: ReportPage | None = None
) -> None:
    """Write :func:`subject_report_html` to ``path`` (replaced atomically)."""
    write_html(path, subject_report_html(store_path, page))


#: The banner :func:`mark_stale` puts at the top of a stopped subject's page, between these two
#: comments, so that :func:`clear_stale` takes exactly it out again (the page as it was written).
STALE_BEGIN = "<!-- scan2morph: stale -->"
STALE_END = "<!-- /scan2morph: stale -->"
_STALE_STYLE = (
    "margin:0 0 1em;padding:.8em 1em;border:3px solid #c00;background:#fee;color:#800;"
    "font-weight:bold"
)


def mark_stale(path: str | Path, note: str) -> bool:
    """Put a banner saying why a page is out of date at the top of a subject's report page (a
    banner there already is replaced).

    For a subject that stopped in a later run: its page, and the store beside it, stay as the
    earlier run wrote them (no result is deleted), and would otherwise look current.

    Parameters
    ----------
    path : str or Path
        ``results/{subject}/report.html``.
    note : str
        The banner's text (HTML-escaped here), e.g. when and why the subject stopped.

    Returns
    -------
    bool
        False when there is no page to mark.
    """
    path = Path(path)
    if not path.is_file():
        return False
    from markupsafe import escape

    text = _without_banner(_read_page(path))
    at = text.find("<body>")
    at = 0 if at < 0 else at + len("<body>")
    banner = (
        f'{STALE_BEGIN}<div role="alert" style="{_STALE_STYLE}">{escape(note)}</div>{STALE_END}'
    )
    write_html(path, text[:at] + banner + text[at:])
    return True


def clear_stale(path: str | Path) -> bool:
    """Take :func:`mark_stale`'s banner out of a report page again, leaving the page as it was
    written: its subject runs again (a stage that is up to date keeps its page).

    Returns
    -------
    bool
        Whether the page had a banner.
    """
    path = Path(path)
    if not path.is_file():
        return False
    text = _read_page(path)
    clean = _without_banner(text)
    if clean == text:
        return False
    write_html(path, clean)
    return True


def _read_page(path: Path) -> str:
    """A page's text as it is on disk (line ends kept: the page comes back byte for byte)."""
    with open(path, encoding="utf-8", newline="") as fh:
        return fh.read()


def _without_banner(text: str) -> str:
    """A page's text without :func:`mark_stale`'s banner."""
    start = text.find(STALE_BEGIN)
    end = text.find(STALE_END, start)
    if start < 0 or end < 0:
        return text
    return text[:start] + text[end + len(STALE_END) :]


def write_html(path: str | Path, text: str) -> None:
    """Write a report page's text to ``path`` (UTF-8, replaced atomically)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with writing(path):
            tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
