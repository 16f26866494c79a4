"""What the subject's report page shows, section by section: the page's data as template blocks.

Each section function returns a list of blocks, dicts with a ``kind`` that
``templates/macros.html.j2`` renders: ``note`` (``text``), ``table`` (``table``: ``columns``,
``rows`` of cells ``{text, numeric}``, ``caption``; optional ``cls`` of a wrapping div),
``columns`` (a TSV's column dictionary folded under its table: ``name``, ``table``),
``thumbs`` (``thumbs``: ``take``, ``uri``, ``width``, ``text``), ``figures`` (``groups``:
``title`` and ``figures`` of ``stem``, ``uri``, ``caption``) and ``viewer`` (the 3D viewer's
context, :func:`scan2morph.report.viewer.viewer_context`). Tables and notes are built by
:mod:`scan2morph.report.blocks` (numbers to 4 significant digits, ``n/a`` for missing or
non-finite values); escaping is the templates'.
"""

from __future__ import annotations

import base64
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import h5py
import numpy as np

from scan2morph.errors import InputError
from scan2morph.report.blocks import note_block, table_block
from scan2morph.store import paths
from scan2morph.store.modal_physics import modal_physics, vertex_coordinates
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


def _attr(obj: h5py.HLObject, key: str, default: str = "") -> str:
    value = obj.attrs.get(key, default)
    return value.decode() if isinstance(value, bytes) else str(value)


def take_order(h5: h5py.File, takes: Sequence[str] | None) -> list[str]:
    """The store's takes in ``takes`` order (the rest after), or by kind (neutral, visemes,
    expressions) and id."""
    present = list(h5[paths.TAKES]) if paths.TAKES in h5 else []
    if takes is not None:
        return [t for t in takes if t in present] + [t for t in present if t not in takes]
    rank = {k: i for i, k in enumerate(KIND_ORDER)}
    return sorted(present, key=lambda t: (rank.get(_attr(h5[paths.take(t)], "kind"), 99), t))


def inputs(h5: h5py.File, takes: list[str], thumbnail_px: int) -> list[dict]:
    """A JPEG thumbnail (``thumbnail_px`` wide) of each take's color image, with kind, label,
    modality and size."""
    if not takes:
        return [note_block("The store holds no takes.")]
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
        # kind and label once each, not repeating the take id ("neutral: neutral neutral")
        said = [" ".join(x for x in dict.fromkeys((kind, label)) if x and x != take)]
        text = ", ".join([*filter(None, said), modality, f"{w}x{h} px"])
        text = f"{take}: {text}{correspondence(h5, take)}"
        items.append({"take": take, "uri": uri, "width": min(w, thumbnail_px), "text": text})
    return [{"kind": "thumbs", "thumbs": items}]


def correspondence(h5: h5py.File, take: str) -> str:
    """How a take's correspondence to the neutral was made, as the end of its caption: refined
    by its texture or by its shape (the refine group's ``used``, ``shape_used``), and
    registered to the subject's other such takes (the takes' consensus); ``""`` for a take
    without a refinement's verdict (the neutral, ``refine.method: none``)."""
    group = h5.get(paths.refine_group(take))
    if group is None or "used" not in group.attrs:
        return ""
    if not bool(group.attrs["used"]):
        return "; template fit kept (see the warnings)"
    if not bool(group.attrs.get("shape_used", False)):
        return "; refined by its texture"
    text = "; refined by its shape (its texture does not correlate with the neutral's)"
    if paths.consensus_group(take) in h5:
        others = len(json.loads(_attr(h5[paths.CONSENSUS], "takes", "[]"))) - 1
        text += f", registered to {others} other such takes by their shared texture"
    return text


def figures(figures: Sequence[ReportFigure]) -> list[dict]:
    """The figures embedded byte for byte, grouped by stage (the stem's prefix)."""
    if not figures:
        return [note_block("No figures were drawn for this subject.")]
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


def status(h5: h5py.File) -> list[dict]:
    """The subject's warnings (a take left out of the models, refused refits, ...) and the
    stages it skipped, first on the page: what not to trust."""
    warnings = read_warnings(h5)
    skipped = skipped_stages(h5)
    parts = []
    if warnings:
        rows = [(w.stage, w.take or "(subject)", w.message) for w in warnings]
        table = table_block(["stage", "take", "warning"], rows, f"{len(warnings)} warnings")
        parts.append(table | {"cls": "warnings"})
    else:
        parts.append(note_block("No warnings: every take passed the quality gates."))
    if skipped:
        parts.append(table_block(["skipped", "why"], sorted(skipped.items()), "Stages not run"))
    return parts


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
    columns = table_block(["column", "unit", "definition"], rows, f"Column dictionary: {table}.tsv")
    return {"kind": "columns", "name": table, "table": columns["table"]}


def pca(h5: h5py.File) -> list[dict]:
    """Tables 1 (eigenvalues, CR, CCR) and 2 (coefficients, mm) of the PCA."""
    if paths.pca("eigenvalues") not in h5:
        return [note_block("The store holds no PCA.")]
    eig, cr, ccr = (h5[paths.pca(k)][()] for k in ("eigenvalues", "cr", "ccr"))
    rows1 = [
        [i + 1, float(e), float(100 * c), float(100 * cc)]
        for i, (e, c, cc) in enumerate(zip(eig, cr, ccr, strict=True))
    ]
    table1 = table_block(
        ["component", "eigenvalue (mm^2)", "CR (%)", "CCR (%)"],
        rows1,
        "Table 1: eigenvalues, contribution rate (CR) and cumulative contribution rate (CCR)",
    )
    coeff = h5[paths.pca("coefficients")][()]
    names = h5[paths.pca("takes")].asstr()[()]
    rows2 = [[str(t), *map(float, row)] for t, row in zip(names, coeff, strict=True)]
    table2 = table_block(
        ["model", *[f"w{i + 1}" for i in range(coeff.shape[1])]],
        rows2,
        "Table 2: PCA coefficients of each model (mm)",
    )
    return [table1, _columns("pca_eigenvalues"), table2, _columns("pca_coefficients")]


def motion_noise(h5: h5py.File) -> list[dict]:
    """The click-noise error of each viseme's motion (mm and % of the motion)."""
    if paths.motion_noise("relative") not in h5:
        return [note_block("The store holds no click-noise estimate.")]
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
    return [table_block(columns, rows, caption), _columns("motion_noise")]


def _projection(h5) -> str:
    """The coordinates' projection: ``Q^T W v`` per vertex (the default), else ``Q^T M v``."""
    if vertex_coordinates(h5):
        return "Q^T W v (W: the mass shared equally by the vertices)"
    return "Q^T M v"


def modal(h5: h5py.File, n_coordinates: int) -> list[dict]:
    """The first ``n_coordinates`` natural frequencies, the expressions' modal coordinates and
    their reconstruction error against the number of modes."""
    if paths.modal("frequencies_hz") not in h5:
        return [note_block("The store holds no modal basis.")]
    freqs = h5[paths.modal("frequencies_hz")][()]
    n = min(int(n_coordinates), len(freqs))
    preset = paths.modal("preset")
    physics = ""
    if preset in h5:
        physics = (
            f" (physics: preset {h5[preset].asstr()[()]}, config modal.preset; /modal/physics)"
        )
    what = "Natural frequencies"
    if vertex_coordinates(h5):
        # the stored modes are the natural ones orthonormalised per vertex: their frequencies
        # are Rayleigh quotients, out of order (mode 4 below mode 2), not natural frequencies
        what = (
            "Frequencies (Rayleigh quotients, not in ascending order: coordinates 'vertex', the "
            "natural modes orthonormalised per vertex, mode j = natural mode j + the modes "
            "before it)"
        )
    out = [
        table_block(
            ["", *[f"mode {i + 1}" for i in range(n)]],
            [["frequency (Hz)", *map(float, freqs[:n])]],
            f"{what} of the first {n} of {len(freqs)} modes{physics}",
        )
    ]
    exprs = list(h5[paths.EXPRESSIONS]) if paths.EXPRESSIONS in h5 else []
    if not exprs:
        return [*out, note_block("The subject has no expression takes.")]
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
        table_block(
            ["expression", *[f"q{i + 1}" for i in range(n)]],
            rows,
            f"Modal coordinates q = {_projection(h5)} of each expression, first {n} modes",
        )
    )
    out.append(_columns("modal_coordinates"))
    if paths.modal("reconstruction_k") in h5:
        out += _reconstruction(h5, exprs, label)
    out += _outline(h5, exprs, label)
    return out


#: Rows of the reconstruction table: part of the error -> its dataset per expression.
RECONSTRUCTION_PARTS = {
    "total": "reconstruction_rms_mm",
    "normal": "reconstruction_normal_rms_mm",
    "tangential": "reconstruction_tangential_rms_mm",
}


def _scalar(h5: h5py.File, key: str) -> float | None:
    return float(h5[key][()]) if key in h5 else None


def _reconstruction(h5: h5py.File, exprs: list[str], label: Mapping[str, str]) -> list[dict]:
    """Each expression's reconstruction error against K, total then its normal and tangential
    parts, and the fewest modes that reach the target error."""
    ks = h5[paths.modal("reconstruction_k")][()]
    target = _scalar(h5, paths.modal("reconstruction_target_mm"))
    rows = []
    for t in exprs:
        name = f"{t} ({label[t]})" if label[t] else t
        to_target = _scalar(h5, paths.expression(t, "modes_to_target"))
        for part, key in RECONSTRUCTION_PARTS.items():
            if paths.expression(t, key) not in h5:
                continue
            values = list(map(float, h5[paths.expression(t, key)][()]))
            reach = [] if target is None else [to_target if part == "total" else None]
            rows.append([name, part, *values, *reach])
    columns = ["expression", "part", *[f"K = {int(k)}" for k in ks]]
    caption = (
        "RMS error (mm, over all vertices) of each expression rebuilt from its first K modes: "
        "total, and its parts along the neutral's normals (what bending modes rebuild) and "
        "along the surface (sliding)"
    )
    if target is not None:
        columns.append(f"modes for <= {target:g} mm")
        caption += (
            f"; the fewest modes that rebuild it to {target:g} mm RMS (n/a: none of the basis)"
        )
    return [table_block(columns, rows, caption), _columns("modal_reconstruction")]


def _outline(h5: h5py.File, exprs: list[str], label: Mapping[str, str]) -> list[dict]:
    """How much of each expression's displacement sits on the outline and on its clamped part."""
    key = paths.modal("fixed_vertices")
    if key not in h5 or not exprs:
        return []
    fixed = h5[key][()].astype(bool)
    outline_key = paths.modal("outline_vertices")
    outline = h5[outline_key][()].astype(bool) if outline_key in h5 else fixed
    rows = [
        [
            f"{t} ({label[t]})" if label[t] else t,
            _scalar(h5, paths.expression(t, "outline_rms_mm")),
            _scalar(h5, paths.expression(t, "clamped_rms_mm")),
        ]
        for t in exprs
        if paths.expression(t, "outline_rms_mm") in h5
    ]
    if not rows:
        return []
    caption = (
        f"Displacement on the face's outline (RMS of its length, mm): {int(outline.sum())} outline "
        f"vertices, {int((fixed & outline).sum())} clamped (config modal.fixed_outline; no mode "
        "moves a clamped vertex, so what an expression moves there no K rebuilds)"
    )
    strip = float(modal_physics(h5).get("outline_strip_mm", 0.0) or 0.0)
    if strip > 0 and (outline & ~fixed).any():
        caption += (
            f"; the other {int((outline & ~fixed).sum())} are held by the skin beyond the "
            f"outline, a strip {strip:g} mm wide (config modal.outline_strip_mm): the modes move "
            "them"
        )
    columns = ["expression", "on the outline (mm)", "on the clamped vertices (mm)"]
    return [table_block(columns, rows, caption)]


def provenance(
    attrs: Mapping[str, str],
    checksums: Mapping[str, Mapping[str, str]],
    versions: Mapping[str, str],
    timings: Sequence[Mapping[str, object]],
) -> list[dict]:
    """Store attributes, input checksums, software versions and run time per stage."""
    out = [table_block(["attribute", "value"], [[k, v] for k, v in attrs.items()], "Store")]
    rows = [[t, r, h] for t, roles in checksums.items() for r, h in roles.items()]
    out.append(
        table_block(["take", "file", "SHA-256"], rows, "Input checksums")
        if rows
        else note_block("The store lists no input checksums.")
    )
    out.append(
        table_block(
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
            table_block(
                ["stage", "jobs", "wall time (s)", "max RSS (MB)"],
                rows,
                "Run time per stage (Snakemake benchmarks)",
            )
        )
    else:
        out.append(note_block("No benchmark files were found for this subject."))
    return out
