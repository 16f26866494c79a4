"""The per-subject report: one self-contained HTML page (``results/{subject}/report.html``).

The page embeds everything it shows (images as base64 ``data:`` URIs, inline CSS, the glTF and
the one script of the 3D viewer, :mod:`scan2morph.report.viewer`) so it opens from disk with no
server, and declares a Content-Security-Policy that forbids loading anything else (the viewer's
script is allowed by its hash). Sections: the subject's inputs (a thumbnail of each take's color
image), the 3D viewer of the subject's glTF, every figure with a one-line caption, the PCA
tables (Yano and Harada, Tables 1 and 2), the modal coordinates of the expressions and their
reconstruction error against the number of modes, the accuracy against ground truth (synthetic
subjects), and provenance (store attributes, input checksums, software versions, run time per
stage).

The page comes from Jinja2 templates (package data in ``report/templates``: ``subject.html.j2``
the page, ``macros.html.j2`` its blocks, ``viewer.html.j2`` the 3D viewer, ``report.css``) with
autoescaping on, so every text is HTML-escaped; this module only gathers what the page shows.
A section's content is a list of blocks (dicts with a ``kind``: ``note``, ``table``,
``columns``, ``thumbs``, ``figures``, ``viewer``) that ``macros.html.j2`` renders.
"""

from __future__ import annotations

import base64
import functools
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import h5py
import jinja2
import numpy as np
from markupsafe import Markup

from scan2morph.errors import InputError
from scan2morph.report import viewer
from scan2morph.report.provenance import software_versions, store_provenance
from scan2morph.store import open_store, paths
from scan2morph.store.warnings import read_warnings, skipped_stages

#: Image types a report embeds: file suffix -> (MIME type, leading magic bytes).
IMAGE_TYPES = {
    ".png": ("image/png", b"\x89PNG\r\n\x1a\n"),
    ".jpg": ("image/jpeg", b"\xff\xd8\xff"),
    ".jpeg": ("image/jpeg", b"\xff\xd8\xff"),
}
#: Order of the take kinds in the inputs section.
KIND_ORDER = ("neutral", "viseme", "expression")
#: Section titles of the figure stages (file stems are ``{stage}_{name}``).
STAGE_TITLES = {"fit": "Fit", "motion": "Motion", "morph": "Morphable model", "modal": "Modal"}
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


@dataclass(frozen=True)
class ReportFigure:
    """A figure file and its one-line caption."""

    path: Path
    caption: str


def read_caption(path: str | Path) -> str:
    """A reStructuredText caption file as one line of plain text.

    Whitespace runs become single spaces and inline markup (````literal````, ``*emphasis*``,
    ``**strong**``, ```interpreted```) is reduced to its text.

    Raises
    ------
    InputError
        The file does not exist.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "caption file not found")
    text = " ".join(path.read_text(encoding="utf-8").split())
    text = re.sub(r"``(.+?)``", r"\1", text)
    text = re.sub(r"\*\*(.+?)\*\*", r"\1", text)
    text = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"\1", text)
    return re.sub(r"`(.+?)`(_{1,2})?", r"\1", text)


def report_figures(
    figure_files: Sequence[str | Path], caption_files: Sequence[str | Path]
) -> list[ReportFigure]:
    """The figures of a report with their captions: a figure's caption is the caption file of
    the same stem (:func:`read_caption`), else its stem in words."""
    captions = {Path(c).stem: read_caption(c) for c in caption_files}
    return [
        ReportFigure(Path(f), captions.get(Path(f).stem, Path(f).stem.replace("_", " ")))
        for f in figure_files
    ]


def data_uri(data: bytes, mime: str) -> str:
    """``data:{mime};base64,...`` of raw bytes."""
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def image_uri(path: str | Path) -> str:
    """The ``data:`` URI of a PNG or JPEG file.

    Raises
    ------
    InputError
        Unsupported suffix, missing file, or content that is not of the suffix's type.
    """
    path = Path(path)
    kind = IMAGE_TYPES.get(path.suffix.lower())
    if kind is None:
        raise InputError(
            path, f"figure: expected one of {sorted(IMAGE_TYPES)}, got {path.suffix!r}"
        )
    if not path.is_file():
        raise InputError(path, "figure file not found")
    data = path.read_bytes()
    if not data.startswith(kind[1]):
        raise InputError(path, f"figure: not a {kind[0]} file (bad signature)")
    return data_uri(data, kind[0])


def thumbnail_jpeg(color: np.ndarray, width_px: int, quality: int = 85) -> bytes:
    """A color image shrunk to ``width_px`` columns (aspect kept, area averaging), as JPEG.

    Parameters
    ----------
    color : (H, W, 3) uint8, RGB
    width_px : int
        Width of the thumbnail in pixels (an image narrower than this keeps its size).

    Returns
    -------
    bytes
        The JPEG file.
    """
    color = np.asarray(color)
    if color.ndim != 3 or color.shape[2] != 3 or color.dtype != np.uint8:
        raise InputError(
            "thumbnail", f"color: expected (H, W, 3) uint8, got {color.shape} {color.dtype}"
        )
    h, w = color.shape[:2]
    if w > width_px:
        size = (int(width_px), max(1, round(h * width_px / w)))
        color = cv2.resize(color, size, interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", color[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise InputError("thumbnail", "JPEG encoding failed")
    return buf.tobytes()


def _fmt(value: object, spec: str = ".4g") -> str:
    if value is None:
        return "n/a"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "n/a" if not math.isfinite(value) else format(float(value), spec)
    return str(value)


def _table(columns: Sequence[str], rows: Sequence[Sequence[object]], caption: str = "") -> dict:
    """A table block: cells as text (numbers formatted, right-aligned by the template)."""
    cells = [
        [
            {
                "text": _fmt(cell),
                "numeric": isinstance(cell, (int, float, np.number)) and not isinstance(cell, bool),
            }
            for cell in row
        ]
        for row in rows
    ]
    return {"kind": "table", "table": {"columns": list(columns), "rows": cells, "caption": caption}}


def _note(text: str) -> dict:
    return {"kind": "note", "text": text}


def _attr(obj: h5py.HLObject, key: str, default: str = "") -> str:
    value = obj.attrs.get(key, default)
    return value.decode() if isinstance(value, bytes) else str(value)


def _take_order(h5: h5py.File, takes: Sequence[str] | None) -> list[str]:
    present = list(h5[paths.TAKES]) if paths.TAKES in h5 else []
    if takes is not None:
        return [t for t in takes if t in present] + [t for t in present if t not in takes]
    rank = {k: i for i, k in enumerate(KIND_ORDER)}
    return sorted(present, key=lambda t: (rank.get(_attr(h5[paths.take(t)], "kind"), 99), t))


def _inputs_section(h5: h5py.File, takes: list[str], thumbnail_px: int) -> list[dict]:
    if not takes:
        return [_note("The store holds no takes.")]
    items = []
    for take in takes:
        group = h5[paths.take(take)]
        kind, label = _attr(group, "kind", "?"), _attr(group, "label", "?")
        modality = _attr(group, "modality", "?")
        if paths.range_image(take, "color") not in h5:
            items.append({"take": take, "uri": None, "text": f"{take}: no color image"})
            continue
        color = h5[paths.range_image(take, "color")][()]
        h, w = color.shape[:2]
        uri = data_uri(thumbnail_jpeg(color, thumbnail_px), "image/jpeg")
        text = f"{take}: {kind} {label}, {modality}, {w}x{h} px"
        items.append({"take": take, "uri": uri, "width": min(w, thumbnail_px), "text": text})
    return [{"kind": "thumbs", "thumbs": items}]


def _figures_section(figures: Sequence[ReportFigure]) -> list[dict]:
    if not figures:
        return [_note("No figures were drawn for this subject.")]
    groups: dict[str, list[dict]] = {}
    for fig in figures:
        stem = Path(fig.path).stem
        stage = stem.split("_", 1)[0] if "_" in stem else "other"
        groups.setdefault(stage, []).append(
            {"stem": stem, "uri": image_uri(fig.path), "caption": fig.caption}
        )
    titles = [
        {"title": STAGE_TITLES.get(stage, stage.capitalize()), "figures": figs}
        for stage, figs in groups.items()
    ]
    return [{"kind": "figures", "groups": titles}]


def _status_blocks(h5: h5py.File) -> list[dict]:
    """The subject's warnings (a take left out of the models, refused refits, ...) and the
    stages it skipped, first on the page: what not to trust."""
    warnings = read_warnings(h5)
    skipped = skipped_stages(h5)
    parts = []
    if warnings:
        rows = [(w.stage, w.take or "(subject)", w.message) for w in warnings]
        table = _table(["stage", "take", "warning"], rows, f"{len(warnings)} warnings")
        parts.append(table | {"cls": "warnings"})
    else:
        parts.append(_note("No warnings: every take passed the quality gates."))
    if skipped:
        parts.append(_table(["skipped", "why"], sorted(skipped.items()), "Stages not run"))
    return parts


def _status_section(h5: h5py.File) -> str:
    """The HTML of the page's first section (:func:`_status_blocks` rendered)."""
    return render_blocks(_status_blocks(h5)).strip()


def _columns(table: str) -> dict:
    """The column dictionary of ``tables/{table}.tsv`` (:mod:`scan2morph.tables`), folded
    under the page's table that shows the same numbers."""
    from scan2morph import tables

    dictionary = {
        "pca_eigenvalues": tables.PCA_EIGENVALUES,
        "pca_coefficients": tables.PCA_COEFFICIENTS,
        "motion_noise": tables.MOTION_NOISE,
        "modal_coordinates": tables.MODAL_COORDINATES,
        "modal_reconstruction": tables.MODAL_RECONSTRUCTION,
    }[table]
    rows = [[c.name, c.unit, c.definition] for c in dictionary]
    columns = _table(["column", "unit", "definition"], rows, f"Column dictionary: {table}.tsv")
    return {"kind": "columns", "name": table, "table": columns["table"]}


def _pca_section(h5: h5py.File) -> list[dict]:
    if paths.pca("eigenvalues") not in h5:
        return [_note("The store holds no PCA.")]
    eig, cr, ccr = (h5[paths.pca(k)][()] for k in ("eigenvalues", "cr", "ccr"))
    rows1 = [
        [i + 1, float(e), float(100 * c), float(100 * cc)]
        for i, (e, c, cc) in enumerate(zip(eig, cr, ccr, strict=True))
    ]
    table1 = _table(
        ["component", "eigenvalue (mm^2)", "CR (%)", "CCR (%)"],
        rows1,
        "Table 1: eigenvalues, contribution rate (CR) and cumulative contribution rate (CCR)",
    )
    coeff = h5[paths.pca("coefficients")][()]
    names = h5[paths.pca("takes")].asstr()[()]
    rows2 = [[str(t), *map(float, row)] for t, row in zip(names, coeff, strict=True)]
    table2 = _table(
        ["model", *[f"w{i + 1}" for i in range(coeff.shape[1])]],
        rows2,
        "Table 2: PCA coefficients of each model (mm)",
    )
    return [table1, _columns("pca_eigenvalues"), table2, _columns("pca_coefficients")]


def _motion_noise_section(h5: h5py.File) -> list[dict]:
    if paths.motion_noise("relative") not in h5:
        return [_note("The store holds no click-noise estimate.")]
    group = h5[paths.MOTION_NOISE]
    names = h5[paths.motion_noise("takes")].asstr()[()]
    rel, err = h5[paths.motion_noise("relative")][()], h5[paths.motion_noise("rms_error_mm")][()]
    failed = h5[paths.motion_noise("failed_draws")][()]
    rows = [
        [str(t), float(e), float(100 * r), f]
        for t, e, r, f in zip(names, err, rel, failed, strict=True)
    ]
    draws, note = _attr(group, "draws", "?"), _attr(group, "click_noise_note", "")
    caption = (
        f"Error that landmark clicks add to each viseme's motion, over the unmasked vertices: "
        f"{draws} refits with the landmarks perturbed by the click noise, {note} "
        "(config motion_noise). A viseme whose motion is small against it is dominated by the "
        "clicking"
    )
    columns = ["viseme", "click-noise error (mm)", "of the motion (%)", "refits refused"]
    return [_table(columns, rows, caption), _columns("motion_noise")]


def _modal_section(h5: h5py.File, n_coordinates: int) -> list[dict]:
    if paths.modal("frequencies_hz") not in h5:
        return [_note("The store holds no modal basis.")]
    freqs = h5[paths.modal("frequencies_hz")][()]
    n = min(int(n_coordinates), len(freqs))
    out = [
        _table(
            ["", *[f"mode {i + 1}" for i in range(n)]],
            [["frequency (Hz)", *map(float, freqs[:n])]],
            f"Natural frequencies of the first {n} of {len(freqs)} modes",
        )
    ]
    exprs = list(h5[paths.EXPRESSIONS]) if paths.EXPRESSIONS in h5 else []
    if not exprs:
        return [*out, _note("The subject has no expression takes.")]
    label = {t: _attr(h5[paths.take(t)], "label", "") if paths.take(t) in h5 else "" for t in exprs}
    rows = [
        [
            f"{t} ({label[t]})" if label[t] else t,
            *map(float, h5[paths.expression(t, "coordinates")][:n]),
        ]
        for t in exprs
        if paths.expression(t, "coordinates") in h5
    ]
    out.append(
        _table(
            ["expression", *[f"q{i + 1}" for i in range(n)]],
            rows,
            f"Modal coordinates q = Q^T M v of each expression, first {n} modes",
        )
    )
    out.append(_columns("modal_coordinates"))
    if paths.modal("reconstruction_k") in h5:
        ks = h5[paths.modal("reconstruction_k")][()]
        rows = [
            [t, *map(float, h5[paths.expression(t, "reconstruction_rms_mm")][()])]
            for t in exprs
            if paths.expression(t, "reconstruction_rms_mm") in h5
        ]
        out.append(
            _table(
                ["expression", *[f"K = {int(k)}" for k in ks]],
                rows,
                "RMS error (mm) of each expression rebuilt from its first K modes",
            )
        )
        out.append(_columns("modal_reconstruction"))
    return out


def _flatten(entry: Mapping, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in entry.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out |= _flatten(value, f"{name} ")
        elif isinstance(value, (list, tuple)):
            out[name] = json.dumps(value)
        else:
            out[name] = value
    return out


def _accuracy_section(accuracy: Mapping | None) -> list[dict]:
    if accuracy is None:
        return [_note("No ground truth: accuracy is measured on synthetic subjects only.")]
    out = []
    units = accuracy.get("units")
    if isinstance(units, Mapping):
        out.append(_note("Units: " + ", ".join(f"{k} in {v}" for k, v in units.items()) + "."))
    summary = accuracy.get("summary", {})
    if isinstance(summary, Mapping) and summary:
        out.append(
            _table(
                ["metric", "value"],
                [[k, v] for k, v in _flatten(summary).items()],
                "Summary (worst take)",
            )
        )
    takes = accuracy.get("takes", {})
    if isinstance(takes, Mapping) and takes:
        flat = {
            t: _flatten(v) if isinstance(v, Mapping) else {"value": v} for t, v in takes.items()
        }
        columns = list(dict.fromkeys(k for row in flat.values() for k in row))
        rows = [[t, *[row.get(c) for c in columns]] for t, row in flat.items()]
        out.append(_table(["take", *columns], rows, "Per take"))
    return out or [_note("The accuracy file holds no numbers.")]


def _provenance_section(
    attrs: Mapping[str, str],
    checksums: Mapping[str, Mapping[str, str]],
    versions: Mapping[str, str],
    timings: Sequence[Mapping[str, object]],
) -> list[dict]:
    out = [_table(["attribute", "value"], [[k, v] for k, v in attrs.items()], "Store")]
    rows = [[t, r, h] for t, roles in checksums.items() for r, h in roles.items()]
    out.append(
        _table(["take", "file", "SHA-256"], rows, "Input checksums")
        if rows
        else _note("The store lists no input checksums.")
    )
    out.append(
        _table(
            ["software", "version"],
            [[k, v] for k, v in versions.items()],
            "Software (at report time)",
        )
    )
    if timings:
        rows = [
            [t["stage"], int(t["jobs"]), float(t["seconds"]), float(t["max_rss_mb"])]
            for t in timings
        ]
        rows.append(
            [
                "total",
                sum(int(t["jobs"]) for t in timings),
                sum(float(t["seconds"]) for t in timings),
                float("nan"),
            ]
        )
        out.append(
            _table(
                ["stage", "jobs", "wall time (s)", "max RSS (MB)"],
                rows,
                "Run time per stage (Snakemake benchmarks)",
            )
        )
    else:
        out.append(_note("No benchmark files were found for this subject."))
    return out


def subject_report_html(
    store_path: str | Path,
    figures: Sequence[ReportFigure] = (),
    accuracy: Mapping | None = None,
    timings: Sequence[Mapping[str, object]] = (),
    versions: Mapping[str, str] | None = None,
    takes: Sequence[str] | None = None,
    n_coordinates: int = 10,
    thumbnail_px: int = 160,
    glb: str | Path | None = None,
    three_dir: str | Path = viewer.THREE_DIR,
) -> str:
    """The report page of one subject.

    Parameters
    ----------
    store_path : str or Path
        ``results/{subject}/{subject}.h5`` (its major format version is checked).
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

    Returns
    -------
    str
        The HTML document.

    Raises
    ------
    InputError
        Unreadable store, glTF or figure, a figure of an unsupported type, bad checksum attribute.
    """
    if n_coordinates < 1 or thumbnail_px < 1:
        raise InputError("report", "n_coordinates and thumbnail_px: expected positive integers")
    versions = software_versions() if versions is None else versions
    with open_store(store_path) as h5:
        attrs, checksums = store_provenance(h5)
        subject = str(attrs.get("subject", Path(store_path).stem))
        order = _take_order(h5, takes)
        view, script = viewer.viewer_context(glb, h5, order, n_coordinates, three_dir)
        sections = [
            ("status", "Warnings and skipped stages", _status_blocks(h5)),
            ("inputs", "Inputs", _inputs_section(h5, order, thumbnail_px)),
            ("viewer", "3D model (glTF viewer)", [{"kind": "viewer", "viewer": view}]),
            ("figures", "Figures", _figures_section(figures)),
            ("motion-noise", "Viseme motion: click-noise error", _motion_noise_section(h5)),
            ("pca", "PCA (Yano and Harada, Tables 1 and 2)", _pca_section(h5)),
            ("modal", "Modal coordinates", _modal_section(h5, n_coordinates)),
            ("accuracy", "Accuracy against ground truth", _accuracy_section(accuracy)),
            ("provenance", "Provenance", _provenance_section(attrs, checksums, versions, timings)),
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
            sections=[{"id": i, "title": t, "blocks": b} for i, t, b in sections],
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


def write_subject_report(path: str | Path, store_path: str | Path, **kwargs) -> None:
    """Write :func:`subject_report_html` to ``path`` (replaced atomically).

    Keyword arguments are those of :func:`subject_report_html`.
    """
    text = subject_report_html(store_path, **kwargs)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
