"""Parameter sweep summaries: one row per combination and subject, and a plot of each accuracy
metric against each swept key (the sweeps themselves: :mod:`scan2morph.sweep`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from scan2morph.errors import InputError


def sweep_summary(
    results: Sequence[tuple[Mapping[str, object], str, Mapping]],
) -> pd.DataFrame:
    """One row per combination and subject: the swept values, ``subject``, the accuracy summary.

    Parameters
    ----------
    results : sequence of (row, subject, accuracy)
        ``row``: dotted config path -> value; ``accuracy``: ``accuracy.json`` content, whose
        numeric ``summary`` entries become columns.
    """
    records = []
    for row, subject, accuracy in results:
        rec = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in row.items()}
        rec["subject"] = subject
        for key, value in accuracy.get("summary", {}).items():
            if value is None or isinstance(value, (int, float)):
                rec[key] = float("nan") if value is None else float(value)
        records.append(rec)
    return pd.DataFrame.from_records(records)


def plot_sweep(
    table: pd.DataFrame, params: Sequence[str], path: str | Path, dpi: int = 100
) -> None:
    """Each accuracy metric (rows) against each swept key (columns), one colour per subject.

    Markers are combinations; in the panel of one key, a line joins the combinations that differ
    in that key only (the other swept keys equal), so each line is a one-at-a-time slice.
    """
    metrics = [c for c in table.columns if c not in (*params, "subject")]
    if not metrics or not params:
        raise InputError("sweep summary", "no accuracy metric or no swept key to plot")
    # no pyplot: no global state
    fig = Figure(figsize=(3.8 * len(params), 2.6 * len(metrics)), layout="constrained")
    axes = fig.subplots(len(metrics), len(params), squeeze=False)
    subjects = list(dict.fromkeys(table["subject"]))
    for j, param in enumerate(params):
        values = list(dict.fromkeys(table[param]))
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
        pos = {v: float(v) for v in values} if numeric else {v: k for k, v in enumerate(values)}
        others = [p for p in params if p != param]
        for i, metric in enumerate(metrics):
            ax = axes[i, j]
            for c, subject in enumerate(subjects):
                rows = table[table["subject"] == subject]
                x = np.array([pos[v] for v in rows[param]])
                ax.plot(x, rows[metric].astype(float), "o", color=f"C{c}", label=str(subject))
                slices = rows.groupby(others, sort=False) if others else [((), rows)]
                for _, group in slices:
                    if len(group) > 1:
                        xs = np.array([pos[v] for v in group[param]])
                        k = np.argsort(xs)
                        ax.plot(
                            xs[k],
                            group[metric].to_numpy(dtype=float)[k],
                            "-",
                            color=f"C{c}",
                            alpha=0.7,
                        )
            if not numeric:
                ax.set_xticks(range(len(values)), [str(v) for v in values])
            if i == len(metrics) - 1:
                ax.set_xlabel(param)
            if j == 0:
                ax.set_ylabel(metric, fontsize="small")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize="small")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, facecolor="white")


def write_sweep_summary(
    results: Sequence[tuple[Mapping[str, object], str, Mapping]],
    params: Sequence[str],
    table_path: str | Path,
    plot_path: str | Path,
) -> pd.DataFrame:
    """Write :func:`sweep_summary` as TSV and :func:`plot_sweep` as PNG; returns the table."""
    if not results:
        raise InputError("sweep summary", "no sweep results to summarise")
    table = sweep_summary(results)
    Path(table_path).parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(table_path, sep="\t", index=False, float_format="%.6g", na_rep="NA")
    plot_sweep(table, params, plot_path)
    return table
