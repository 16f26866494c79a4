"""The accuracy section of a subject's report: ``accuracy.json`` (errors against the ground
truth of a synthetic subject) as tables, the error against the material motion first."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence

from scan2morph.report.blocks import note_block, table_block
from scan2morph.tables import accuracy_column

#: The summary's caption: what its values are.
SUMMARY_CAPTION = (
    "Summary: each measure's worst take (_max: the largest error, _min: the least of what "
    "should be high, a coverage or a valid share; others: one value of the subject)"
)


def _unit(name: str) -> str:
    """A summary measure's unit (the column dictionary's, or from its name's suffix)."""
    return accuracy_column(name).unit


def summary_tables(summary: Mapping) -> list[dict]:
    """``accuracy.json``'s ``summary`` as a measure / unit / value table, and its
    ``by_modality`` part as one column per modality, its takes listed in the last row (they
    were flattened into one table before: a JSON list in the value column, the units only in
    the names)."""
    scalars = {k: v for k, v in summary.items() if not isinstance(v, (Mapping, list, tuple))}
    out = [
        table_block(
            ["measure", "unit", "value"],
            [[k, _unit(k), v] for k, v in scalars.items()],
            SUMMARY_CAPTION,
        )
    ]
    modalities = summary.get("by_modality")
    if isinstance(modalities, Mapping) and modalities:
        names = list(modalities)
        entries = [m if isinstance(m, Mapping) else {} for m in modalities.values()]
        measures = list(dict.fromkeys(k for e in entries for k in e if k != "takes"))
        rows = [[k, _unit(k), *[e.get(k) for e in entries]] for k in measures]
        rows.append(["takes", "", *[", ".join(map(str, e.get("takes", []))) for e in entries]])
        caption = "Summary by modality: each measure's worst take of that modality"
        out.append(table_block(["measure", "unit", *names], rows, caption))
    return out


def _flatten(entry: Mapping, prefix: str = "") -> dict[str, object]:
    """A nested ``accuracy.json`` entry as one level: ``"mesh rms_mm"`` -> value (the keys
    joined by a space; a list as its JSON text)."""
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


#: The headline columns: error against where the skin really went (``accuracy.json`` keys).
MATERIAL_KEYS = (
    "material_relative_error",
    "material_rms_error_mm",
    "material_normal_rms_error_mm",
    "material_tangential_rms_error_mm",
    "material_rms_mm",
)
#: The method-ideal figure of a viseme (what exact clicks would give), in the same columns.
IDEAL_KEYS = (
    "relative_error",
    "rms_error_mm",
    "normal_rms_error_mm",
    "tangential_rms_error_mm",
    "ideal_rms_mm",
)
MATERIAL_COLUMNS = [
    "take",
    "compared with",
    "error (% of the motion)",
    "RMS error (mm)",
    "normal part (mm)",
    "tangential part (mm)",
    "motion RMS (mm)",
]


def _error_row(take: str, reference: str, entry: Mapping, keys: Sequence[str]) -> list:
    """A row of the material tables: the take, what it is compared with, the relative error in
    % and the other ``keys``' values (None where the entry lacks one)."""
    values = [entry.get(k) for k in keys]
    rel = values[0]
    percent = 100 * rel if isinstance(rel, (int, float)) else None
    return [take, reference, percent, *values[1:]]


def material_tables(takes: Mapping) -> list[dict]:
    """The headline of the accuracy section: each viseme's motion and each expression's
    displacement field against the material motion of the skin (where each skin point really
    went), in % of that motion and in mm, total and split along the normal and the surface;
    each viseme's error against the method-ideal motion follows as its second line."""
    if not isinstance(takes, Mapping):
        return []
    out = []
    rows = []
    for take, entry in takes.items():
        motion = entry.get("motion") if isinstance(entry, Mapping) else None
        if isinstance(motion, Mapping):
            rows.append(_error_row(take, "material motion", motion, MATERIAL_KEYS))
            rows.append(_error_row(take, "method-ideal motion", motion, IDEAL_KEYS))
    if rows:
        caption = (
            "Viseme motion: error against the material motion of the skin (where each skin "
            "point really went; over the unmasked vertices), total and its parts along the "
            "neutral's normal (a wrong surface) and along the surface (skin that slid); second "
            "line: against the method-ideal motion (what exact clicks would give)"
        )
        out.append(table_block(MATERIAL_COLUMNS, rows, caption))
    rows = [
        _error_row(take, "material motion", entry["expression"], MATERIAL_KEYS)
        for take, entry in takes.items()
        if isinstance(entry, Mapping) and isinstance(entry.get("expression"), Mapping)
    ]
    if rows:
        caption = (
            "Expression displacement fields: error against the material motion of the skin "
            "(over all vertices), total and its normal and tangential parts"
        )
        out.append(table_block(MATERIAL_COLUMNS, rows, caption))
    return out


def accuracy(accuracy: Mapping | None) -> list[dict]:
    """``accuracy.json``: first the error against the material motion per viseme and
    expression (:func:`material_tables`), then its units, its summary and one row per take
    (None: no ground truth)."""
    if accuracy is None:
        return [note_block("No ground truth: accuracy is measured on synthetic subjects only.")]
    out = material_tables(accuracy.get("takes", {}))
    units = accuracy.get("units")
    if isinstance(units, Mapping):
        out.append(note_block("Units: " + ", ".join(f"{k} in {v}" for k, v in units.items()) + "."))
    summary = accuracy.get("summary", {})
    if isinstance(summary, Mapping) and summary:
        out += summary_tables(summary)
    takes = accuracy.get("takes", {})
    if isinstance(takes, Mapping) and takes:
        flat = {
            t: _flatten(v) if isinstance(v, Mapping) else {"value": v} for t, v in takes.items()
        }
        columns = list(dict.fromkeys(k for row in flat.values() for k in row))
        rows = [[t, *[row.get(c) for c in columns]] for t, row in flat.items()]
        out.append(table_block(["take", *columns], rows, "Per take"))
    return out or [note_block("The accuracy file holds no numbers.")]


__all__ = [
    "IDEAL_KEYS",
    "MATERIAL_COLUMNS",
    "MATERIAL_KEYS",
    "accuracy",
    "material_tables",
    "summary_tables",
]
