"""The cohort summary: one row per subject (``results/cohort/summary.tsv``) and a comparison plot.

Per subject: the number of takes (and of visemes and expressions), the RMS over all template
vertices of the processed motion's length for each viseme label (mean over repeated takes of a
label), the cumulative contribution rate of the first three principal components, the lowest
natural frequency of the modal basis, and the accuracy summary against ground truth where there
is one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from scan2morph.errors import InputError
from scan2morph.store import open_store, paths
from scan2morph.tol import VISEMES

#: Number of leading CCR values in the table.
N_CCR = 3


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
        ``row``: ``subject``, ``n_takes``, ``n_visemes``, ``n_expressions``,
        ``motion_rms_mm_{label}`` per viseme label, ``motion_noise_relative_{label}`` (the
        click-noise error bar, when the store has ``/motion_noise``), ``ccr_1`` .. ``ccr_3``,
        ``modal_f1_hz``, and the accuracy summary keys; ``ccr``: the whole CCR curve.

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
        row: dict[str, object] = {
            "subject": _attr(h5, "subject") or Path(store_path).stem,
            "n_takes": len(kinds),
            "n_visemes": sum(k == "viseme" for k in kinds.values()),
            "n_expressions": sum(k == "expression" for k in kinds.values()),
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
            row[f"motion_rms_mm_{label}"] = float(np.mean(by_label[label]))
        for label in sorted(noise_by_label, key=lambda lab: (order.get(lab, len(order)), lab)):
            row[f"motion_noise_relative_{label}"] = float(np.mean(noise_by_label[label]))
        ccr = np.asarray(h5[paths.pca("ccr")][()] if paths.pca("ccr") in h5 else [], dtype=float)
        for i in range(N_CCR):
            row[f"ccr_{i + 1}"] = float(ccr[i]) if i < len(ccr) else float("nan")
        freqs = h5[paths.modal("frequencies_hz")][()]
        row["modal_f1_hz"] = float(freqs[0]) if len(freqs) else float("nan")
    summary = (accuracy or {}).get("summary", {})
    for key, value in summary.items():
        if isinstance(value, (int, float)) or value is None:
            row[key] = float("nan") if value is None else float(value)
    return SubjectSummary(row, ccr)


def cohort_table(summaries: Sequence[SubjectSummary]) -> pd.DataFrame:
    """Rows of several subjects in one table; a column a subject lacks is NaN there.

    Column order: the identification and count columns, motion per label (paper order, then
    others), click-noise error per label (the same order), CCR, frequency, then accuracy columns
    in first-seen order.
    """
    columns: list[str] = []
    for s in summaries:
        columns += [c for c in s.row if c not in columns]
    motion = []
    for prefix in ("motion_rms_mm_", "motion_noise_relative_"):
        order = {f"{prefix}{v}": i for i, v in enumerate(VISEMES)}
        group = [c for c in columns if c.startswith(prefix)]
        motion += sorted(group, key=lambda c: (order.get(c, len(order)), c))
    head = ["subject", "n_takes", "n_visemes", "n_expressions"]
    fixed = [f"ccr_{i + 1}" for i in range(N_CCR)] + ["modal_f1_hz"]
    rest = [c for c in columns if c not in head + motion + fixed]
    return pd.DataFrame([s.row for s in summaries], columns=head + motion + fixed + rest)


def plot_cohort(
    table: pd.DataFrame, ccr: Mapping[str, np.ndarray], path: str | Path, dpi: int = 110
) -> None:
    """Compare subjects: motion RMS per viseme label, CCR curves, accuracy where known.

    Parameters
    ----------
    table : DataFrame
        :func:`cohort_table`.
    ccr : mapping subject -> (K,) CCR curve
    path : str or Path
        PNG written.
    """
    motion_cols = [c for c in table.columns if c.startswith("motion_rms_mm_")]
    fixed = {"subject", "n_takes", "n_visemes", "n_expressions", "modal_f1_hz"}
    acc_cols = [
        c
        for c in table.columns
        if c not in fixed and c not in motion_cols and not c.startswith("ccr_")
    ]
    has_acc = bool(acc_cols) and table[acc_cols].notna().any().any()
    n_panels = 3 if has_acc else 2
    fig = Figure(figsize=(5.2 * n_panels, 4.2), layout="constrained")  # no pyplot: no global state
    axes = fig.subplots(1, n_panels)
    subjects = list(table["subject"])
    width = 0.8 / max(len(subjects), 1)
    ax = axes[0]
    labels = [c.removeprefix("motion_rms_mm_") for c in motion_cols]
    x = np.arange(len(labels))
    for i, (_, row) in enumerate(table.iterrows()):
        ax.bar(
            x + (i - (len(subjects) - 1) / 2) * width,
            row[motion_cols].astype(float),
            width,
            label=row["subject"],
        )
    ax.set_xticks(x, labels)
    ax.set_ylabel("motion RMS over vertices (mm)")
    ax.set_title("Viseme motion magnitude")
    if not labels:
        ax.text(0.5, 0.5, "no viseme takes", ha="center", transform=ax.transAxes)
    ax.legend(fontsize="small")
    ax = axes[1]
    for subject in subjects:
        curve = np.asarray(ccr.get(subject, []), dtype=float)
        ax.plot(np.arange(1, len(curve) + 1), 100 * curve, marker="o", label=subject)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("number of principal components")
    ax.set_ylabel("CCR (%)")
    ax.set_title("Cumulative contribution rate")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    if has_acc:
        ax = axes[2]
        known = table[table[acc_cols].notna().any(axis=1)]
        xa = np.arange(len(acc_cols))
        wa = 0.8 / max(len(known), 1)
        for i, (_, row) in enumerate(known.iterrows()):
            ax.bar(
                xa + (i - (len(known) - 1) / 2) * wa,
                row[acc_cols].astype(float),
                wa,
                label=row["subject"],
            )
        ax.set_xticks(xa, acc_cols, rotation=35, ha="right", fontsize="small")
        ax.set_title("Accuracy against ground truth (worst take)")
        ax.set_ylabel("mm, degrees or fraction (see name)")
        ax.legend(fontsize="small")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, facecolor="white")


def write_cohort_summary(
    stores: Mapping[str, str | Path],
    accuracies: Mapping[str, Mapping],
    table_path: str | Path,
    plot_path: str | Path,
) -> pd.DataFrame:
    """Summarise subjects into ``table_path`` (TSV) and ``plot_path`` (PNG).

    Parameters
    ----------
    stores : mapping subject -> store path, in table order
    accuracies : mapping subject -> accuracy.json content (subjects with ground truth)

    Returns
    -------
    DataFrame
        The table written.
    """
    if not stores:
        raise InputError("cohort", "no subjects to summarise")
    summaries = {s: subject_summary(p, accuracies.get(s)) for s, p in stores.items()}
    table = cohort_table(list(summaries.values()))
    Path(table_path).parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(table_path, sep="\t", index=False, float_format="%.6g", na_rep="NA")
    plot_cohort(table, {str(v.row["subject"]): v.ccr for v in summaries.values()}, plot_path)
    return table
