"""The cohort summary: one row per subject (``results/cohort/summary.tsv``) and a comparison plot.

Per subject, first (synthetic subjects): the error against the material motion of the skin
(where each skin point really went, ``accuracy.json``) per viseme label and per expression
label, in total and in its normal and tangential (sliding) parts, and for the visemes the error
against the method-ideal motion (what perfect clicks would give) as the second figure. Then the
number of takes (and of visemes and expressions), the RMS over all template
vertices of the processed motion's length for each viseme label (mean over repeated takes of a
label), the click-noise error bar per label, the cumulative contribution rate of the first three
principal components, the lowest natural frequency of the modal basis, and the accuracy summary
against ground truth where there is one. The table's column dictionary is
:data:`scan2morph.tables.COHORT` (and :func:`scan2morph.tables.accuracy_column`).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from scan2morph.errors import InputError, writing
from scan2morph.store import open_store, paths
from scan2morph.store.warnings import read_failures as left_out
from scan2morph.tables import COHORT, accuracy_column, write_table
from scan2morph.tol import VISEMES

log = logging.getLogger("scan2morph")

#: Number of leading CCR values in the table.
N_CCR = 3
#: Column prefixes of the per-label families: motion RMS over all vertices, click-noise error bar.
MOTION_PREFIX, NOISE_PREFIX = "motion_rms_all_mm_", "noise_relative_unmasked_"
#: Per-label accuracy columns, in table order: (take kind, accuracy.json entry, key, column
#: prefix). The material error leads; the method-ideal figure (visemes only) follows it.
_MATERIAL_KEYS = (
    "material_relative_error",
    "material_rms_error_mm",
    "material_normal_rms_error_mm",
    "material_tangential_rms_error_mm",
)
MATERIAL_FAMILIES = (
    *(("viseme", "motion", key, f"{key}_viseme_") for key in _MATERIAL_KEYS),
    ("viseme", "motion", "relative_error", "ideal_relative_error_viseme_"),
    *(("expression", "expression", key, f"{key}_expression_") for key in _MATERIAL_KEYS),
)
MATERIAL_PREFIXES = tuple(f[3] for f in MATERIAL_FAMILIES)
#: Panels of the accuracy part of the plot, one per unit: unit -> axis label.
UNIT_LABELS = {
    "mm": "mm",
    "deg": "degrees",
    "fraction": "fraction",
    "px": "px",
    "Hz": "Hz",
    "-": "no unit",
}


@dataclass(frozen=True)
class SubjectSummary:
    """One subject's row of the cohort table and its full CCR curve (K,)."""

    row: dict[str, object]
    ccr: np.ndarray


def motion_rms(motion: np.ndarray) -> float:
    """RMS over vertices of the motion vectors' length, mm.

    Parameters
    ----------
    motion : (V, 3) float, mm (NaN rows are ignored)
    """
    motion = np.asarray(motion, dtype=np.float64)
    ok = np.isfinite(motion).all(axis=1)
    return float(np.sqrt(np.mean(np.sum(motion[ok] ** 2, axis=1)))) if ok.any() else float("nan")


def _attr(obj, key: str) -> str:
    value = obj.attrs.get(key, "")
    return value.decode() if isinstance(value, bytes) else str(value)


def subject_summary(store_path: str | Path, accuracy: Mapping | None = None) -> SubjectSummary:
    """The cohort-table row of one subject.

    Parameters
    ----------
    store_path : str or Path
        ``results/{subject}/{subject}.h5``.
    accuracy : mapping, optional
        ``accuracy.json`` content; its ``summary`` values become columns.

    Returns
    -------
    SubjectSummary
        ``row``: ``subject``, ``n_takes``, ``n_visemes``, ``n_expressions``, ``left_out`` (the
        takes left out of the subject, with the stage that refused each; NaN when none), the per-label
        accuracy columns of :data:`MATERIAL_FAMILIES` (:func:`material_columns`),
        ``motion_rms_all_mm_{label}`` per viseme label (RMS over all vertices),
        ``noise_relative_unmasked_{label}`` (the click-noise error bar, over the vertices outside
        the mask, when the store has ``/motion_noise``), ``ccr_1`` .. ``ccr_3``, ``modal_f1_hz``,
        and the accuracy summary keys; ``ccr``: the whole CCR curve.

    Raises
    ------
    InputError
        Unreadable store, or one without modal frequencies. A subject without visemes has no
        PCA: its CCR columns are NaN.
    """
    with open_store(store_path) as h5:
        for need in (paths.modal("frequencies_hz"),):
            if need not in h5:
                raise InputError(store_path, f"{need}: missing (the subject did not finish)")
        takes = h5[paths.TAKES] if paths.TAKES in h5 else {}
        kinds = {t: _attr(takes[t], "kind") for t in takes}
        labels = {t: _attr(takes[t], "label") or t for t in takes}
        row: dict[str, object] = {
            "subject": _attr(h5, "subject") or Path(store_path).stem,
            "n_takes": len(kinds),
            "n_visemes": sum(k == "viseme" for k in kinds.values()),
            "n_expressions": sum(k == "expression" for k in kinds.values()),
            "left_out": "; ".join(f"{t} ({f.stage})" for t, f in left_out(h5).items())
            or float("nan"),
        }
        by_label: dict[str, list[float]] = {}
        for take in h5[paths.VISEMES] if paths.VISEMES in h5 else []:
            label = _attr(takes[take], "label") if take in takes else take
            by_label.setdefault(label or take, []).append(
                motion_rms(h5[paths.viseme(take, "motion")][()])
            )
        noise_by_label: dict[str, list[float]] = {}
        if paths.motion_noise("relative") in h5:
            names = h5[paths.motion_noise("takes")].asstr()[()]
            for take, rel in zip(names, h5[paths.motion_noise("relative")][()], strict=True):
                label = _attr(takes[take], "label") if take in takes else take
                noise_by_label.setdefault(label or take, []).append(float(rel))
        order = {v: i for i, v in enumerate(VISEMES)}
        for label in sorted(by_label, key=lambda lab: (order.get(lab, len(order)), lab)):
            row[f"{MOTION_PREFIX}{label}"] = float(np.mean(by_label[label]))
        for label in sorted(noise_by_label, key=lambda lab: (order.get(lab, len(order)), lab)):
            bars = [v for v in noise_by_label[label] if np.isfinite(v)]  # a take without: NaN
            row[f"{NOISE_PREFIX}{label}"] = float(np.mean(bars)) if bars else float("nan")
        ccr = np.asarray(h5[paths.pca("ccr")][()] if paths.pca("ccr") in h5 else [], dtype=float)
        for i in range(N_CCR):
            row[f"ccr_{i + 1}"] = float(ccr[i]) if i < len(ccr) else float("nan")
        freqs = h5[paths.modal("frequencies_hz")][()]
        row["modal_f1_hz"] = float(freqs[0]) if len(freqs) else float("nan")
    row |= material_columns(accuracy, kinds, labels)
    summary = (accuracy or {}).get("summary", {})
    for key, value in summary.items():
        if isinstance(value, (int, float)) or value is None:
            row[key] = float("nan") if value is None else float(value)
    return SubjectSummary(row, ccr)


def _label_order(label: str) -> tuple:
    order = {v: i for i, v in enumerate(VISEMES)}
    return (order.get(label, len(order)), label)


def material_columns(
    accuracy: Mapping | None, kinds: Mapping[str, str], labels: Mapping[str, str]
) -> dict[str, float]:
    """The per-label accuracy columns of one subject: for each family of
    :data:`MATERIAL_FAMILIES`, the mean over the takes of a label of the take's value in
    ``accuracy.json`` (a missing or null value is left out; a label with none is NaN).

    Parameters
    ----------
    accuracy : mapping or None
        ``accuracy.json`` content (``takes`` -> take -> ``motion`` / ``expression`` entries).
    kinds, labels : mapping take -> kind / label
        From the store.

    Returns
    -------
    dict column -> value
        Families in :data:`MATERIAL_FAMILIES` order, labels in paper order then by name.
    """
    takes = (accuracy or {}).get("takes", {}) or {}
    out: dict[str, float] = {}
    for kind, entry, key, prefix in MATERIAL_FAMILIES:
        by_label: dict[str, list[float]] = {}
        for take, record in takes.items():
            if kinds.get(take) != kind or not isinstance(record, Mapping):
                continue
            values = by_label.setdefault(labels.get(take, take), [])
            value = (record.get(entry) or {}).get(key)
            if isinstance(value, (int, float)) and np.isfinite(value):
                values.append(float(value))
        for label in sorted(by_label, key=_label_order):
            values = by_label[label]
            out[f"{prefix}{label}"] = float(np.mean(values)) if values else float("nan")
    return out


def cohort_table(summaries: Sequence[SubjectSummary]) -> pd.DataFrame:
    """Rows of several subjects in one table; a column a subject lacks is NaN there.

    Column order: the identification and count columns, the error against the material motion
    per viseme and per expression label (:data:`MATERIAL_FAMILIES`: total, normal, tangential,
    then the visemes' method-ideal figure), motion per label (paper order, then others),
    click-noise error per label (the same order), CCR, frequency, then accuracy columns in
    first-seen order.
    """
    columns: list[str] = []
    for s in summaries:
        columns += [c for c in s.row if c not in columns]
    motion = []
    for prefix in (*MATERIAL_PREFIXES, MOTION_PREFIX, NOISE_PREFIX):
        group = [c for c in columns if c.startswith(prefix) and _family(c) == prefix]
        motion += sorted(group, key=lambda c: _label_order(c.removeprefix(prefix)))
    head = ["subject", "n_takes", "n_visemes", "n_expressions", "left_out", "stopped"]
    fixed = [f"ccr_{i + 1}" for i in range(N_CCR)] + ["modal_f1_hz"]
    rest = [c for c in columns if c not in head + motion + fixed]
    return pd.DataFrame([s.row for s in summaries], columns=head + motion + fixed + rest)


def _family(column: str) -> str | None:
    """The per-label prefix a column belongs to (the longest that matches), or None."""
    hits = [p for p in (*MATERIAL_PREFIXES, MOTION_PREFIX, NOISE_PREFIX) if column.startswith(p)]
    return max(hits, key=len) if hits else None


def accuracy_columns(table: pd.DataFrame) -> list[str]:
    """The accuracy summary columns of a cohort table (those after the fixed ones)."""
    fixed = {c.name for c in COHORT if not c.is_pattern}
    return [
        c
        for c in table.columns
        if c not in fixed and _family(c) is None and not c.startswith("ccr_")
    ]


def _bars(
    ax, rows: pd.DataFrame, columns: Sequence[str], labels: Sequence[str], colour: Mapping
) -> None:
    """One group of bars per column, one bar per subject (``colour``: subject -> colour index)."""
    x = np.arange(len(columns))
    width = 0.8 / max(len(rows), 1)
    for i, (_, row) in enumerate(rows.iterrows()):
        ax.bar(
            x + (i - (len(rows) - 1) / 2) * width,
            row[list(columns)].astype(float),
            width,
            color=f"C{colour[row['subject']]}",
            label=row["subject"],
        )
    rotate = any(len(str(lab)) > 8 for lab in labels)
    ax.set_xticks(x, labels, rotation=30 if rotate else 0, ha="right" if rotate else "center")
    pad = max(0.0, (3 - len(columns)) / 2)  # a lone metric keeps slim bars
    ax.set_xlim(-0.5 - pad, len(columns) - 0.5 + pad)
    ax.grid(axis="y", alpha=0.3)


def _material_panel(ax, table: pd.DataFrame, rel: Mapping[str, list[str]], colour) -> None:
    """The headline: error against the material motion per viseme and expression label (%),
    bars per subject; the visemes' method-ideal error as a black tick on each bar."""
    columns = [*rel["viseme"], *rel["expression"]]
    labels = [
        f"{c.removeprefix(f'material_relative_error_{kind}_')}"
        + (" (expr.)" if kind == "expression" else "")
        for kind in ("viseme", "expression")
        for c in rel[kind]
    ]
    scaled = table.copy()
    scaled[columns] = 100 * scaled[columns].astype(float)
    _bars(ax, scaled, columns, labels, colour)
    x = np.arange(len(columns))
    width = 0.8 / max(len(table), 1)
    for i, (_, row) in enumerate(table.iterrows()):
        for j, c in enumerate(rel["viseme"]):
            ideal = (
                f"ideal_relative_error_viseme_{c.removeprefix('material_relative_error_viseme_')}"
            )
            if ideal in row and np.isfinite(float(row[ideal])):
                xi = x[j] + (i - (len(table) - 1) / 2) * width
                ax.plot(
                    [xi - width / 2, xi + width / 2],
                    [100 * float(row[ideal])] * 2,
                    color="black",
                    lw=2,
                    label="method-ideal" if i == 0 and j == 0 else None,
                )
    ax.set_ylabel("error against the material motion (%)")
    ax.set_title("Motion error against where the skin went (%)")
    ax.legend(fontsize="small")


def plot_cohort(
    table: pd.DataFrame, ccr: Mapping[str, np.ndarray], path: str | Path, dpi: int = 110
) -> None:
    """Compare subjects, one panel per unit: first (subjects with ground truth) the error
    against the material motion per viseme and expression label (%, the method-ideal error as
    a black tick on the viseme bars), then motion RMS per viseme label (mm), CCR curves
    (fraction, as %), and the accuracy against ground truth where known, one panel for each of
    its units (mm, degrees, fraction, px: the metric's unit in the column dictionary).

    Parameters
    ----------
    table : DataFrame
        :func:`cohort_table`.
    ccr : mapping subject -> (K,) CCR curve
    path : str or Path
        PNG written.
    """
    motion_cols = [c for c in table.columns if c.startswith(MOTION_PREFIX)]
    rel = {
        kind: [
            c
            for c in table.columns
            if _family(c) == f"material_relative_error_{kind}_" and table[c].notna().any()
        ]
        for kind in ("viseme", "expression")
    }
    material = rel["viseme"] + rel["expression"]
    acc_cols = [c for c in accuracy_columns(table) if table[c].notna().any()]
    known = table[table[acc_cols].notna().any(axis=1)] if acc_cols else table.iloc[:0]
    # one panel per unit, the minima of what should be high (a coverage, a valid share: *_min)
    # apart from the errors beside them
    by_unit: dict[tuple[str, bool], list[str]] = {}
    for c in acc_cols:
        by_unit.setdefault((accuracy_column(c).unit, c.endswith("_min")), []).append(c)
    order = {u: i for i, u in enumerate(UNIT_LABELS)}
    units = sorted(by_unit, key=lambda u: (order.get(u[0], len(order)), u))
    lead = 1 if material else 0
    n_panels = lead + 2 + len(units)
    n_cols = min(n_panels, 3)
    n_rows = -(-n_panels // n_cols)
    # no pyplot: no global state
    fig = Figure(figsize=(5.2 * n_cols, 4.2 * n_rows), layout="constrained")
    axes = fig.subplots(n_rows, n_cols, squeeze=False).ravel()
    subjects = list(table["subject"])
    colour = {s: i for i, s in enumerate(subjects)}
    if material:
        _material_panel(axes[0], table, rel, colour)
        axes = axes[1:]
    ax = axes[0]
    _bars(ax, table, motion_cols, [c.removeprefix(MOTION_PREFIX) for c in motion_cols], colour)
    ax.set_ylabel("motion RMS over all vertices (mm)")
    ax.set_title("Viseme motion magnitude (mm)")
    if not motion_cols:
        ax.text(0.5, 0.5, "no viseme takes", ha="center", transform=ax.transAxes)
    ax.legend(fontsize="small")
    ax = axes[1]
    for i, subject in enumerate(subjects):
        curve = np.asarray(ccr.get(subject, []), dtype=float)
        ax.plot(np.arange(1, len(curve) + 1), 100 * curve, "o-", color=f"C{i}", label=subject)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("number of principal components")
    ax.set_ylabel("CCR (%)")
    ax.set_ylim(0, 100)  # from 0: a narrow axis made the subjects' spread look large
    ax.set_title("Cumulative contribution rate (%)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    for ax, (unit, least) in zip(axes[2:], units, strict=False):
        _bars(ax, known, by_unit[unit, least], by_unit[unit, least], colour)
        label = UNIT_LABELS.get(unit, unit)
        ax.set_ylabel(label)
        kind = "the least of each, higher is better" if least else label
        ax.set_title(f"Accuracy against ground truth ({kind})")
        ax.legend(fontsize="small")
    for ax in axes[n_panels - lead :]:
        ax.set_visible(False)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with writing(path):
        fig.savefig(path, dpi=dpi, facecolor="white")


def write_cohort_summary(
    stores: Mapping[str, str | Path],
    accuracies: Mapping[str, Mapping],
    table_path: str | Path,
    plot_path: str | Path,
    stopped: Mapping[str, str] | None = None,
) -> pd.DataFrame:
    """Summarise subjects into ``table_path`` (TSV with its column dictionary on top) and
    ``plot_path`` (PNG).

    Parameters
    ----------
    stores : mapping subject -> store path, in table order
    accuracies : mapping subject -> accuracy.json content (subjects with ground truth)
    stopped : mapping subject -> why, optional
        Subjects that did not finish: a row each after the others, with the reason in its
        ``stopped`` column and nothing else; the plot leaves them out.

    Returns
    -------
    DataFrame
        The table written.
    """
    if not stores:
        why = "; ".join(f"{s}: {w}" for s, w in (stopped or {}).items())
        raise InputError(
            "cohort", "no subject to summarise" + (f" (stopped: {why})" if why else "")
        )
    summaries = {s: subject_summary(p, accuracies.get(s)) for s, p in stores.items()}
    for subject, path in stores.items():
        with open_store(path) as h5:
            for failure in left_out(h5).values():  # in the job's log; the run's last lines
                log.info("%s/%s", subject, failure)  # print them (once for the whole run)
    table = cohort_table(list(summaries.values()))
    dictionary = [*COHORT, *(accuracy_column(c) for c in accuracy_columns(table))]
    plot_cohort(table, {str(v.row["subject"]): v.ccr for v in summaries.values()}, plot_path)
    if stopped:
        rows = pd.DataFrame([{"subject": s, "stopped": w} for s, w in stopped.items()])
        table = pd.concat([table, rows.reindex(columns=table.columns)], ignore_index=True)
    write_table(table_path, table, dictionary)
    return table
