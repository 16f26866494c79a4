"""Parameter sweep summaries: one row per combination and subject, and a plot of each accuracy
metric against the swept key that varied (the sweeps themselves: :mod:`scan2morph.sweep`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from scan2morph.errors import InputError, writing
from scan2morph.tables import REFUSED, accuracy_column, sweep_dictionary, write_table

#: Panel rows of the plot, one per unit: unit -> axis label (other units follow, by name).
UNIT_LABELS = {"mm": "mm", "deg": "degrees", "fraction": "fraction", "px": "px", "Hz": "Hz"}
_MARKERS = ("o", "s", "^", "D", "v", "P", "X")
#: Line styles of the subjects: not dashed (the config's value) nor dotted (the config's row).
_LINES = ("-", "-.", (0, (3, 1, 1, 1, 1, 1)))


def config_values(config: Mapping, params: Sequence[str]) -> dict[str, object]:
    """The config's value of each swept key.

    Parameters
    ----------
    config : mapping
        The config, or the sections a sweep reads (:func:`scan2morph.sweep.sweep_settings`).
    params : sequence of str
        Dotted config paths (``mask.radius_mm``).

    Raises
    ------
    InputError
        A path the config does not hold.
    """
    out = {}
    for param in params:
        node = config
        for part in param.split("."):
            if not isinstance(node, Mapping) or part not in node:
                raise InputError("sweep summary", f"{param}: not in the config (no default value)")
            node = node[part]
        out[param] = node
    return out


def _number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def _same(a, b) -> bool:
    """Two swept values are the same (20 and 20.0 are)."""
    if _number(a) and _number(b):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return str(a) == str(b)


def one_at_a_time(
    table: pd.DataFrame, params: Sequence[str], defaults: Mapping[str, object]
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Which rows are the config's own combination, and which vary one key only.

    Returns
    -------
    default : (N,) bool
        Rows equal to ``defaults`` in every swept key.
    varied : dict key -> (N,) bool
        Rows that differ from ``defaults`` in exactly that key. Rows differing in two or more
        keys are in neither.
    """
    differs = {
        p: np.array([not _same(v, defaults[p]) for v in table[p]], dtype=bool) for p in params
    }
    n_diff = np.sum([differs[p] for p in params], axis=0) if params else np.zeros(len(table), int)
    default = n_diff == 0
    return default, {p: differs[p] & (n_diff == 1) for p in params}


def sweep_summary(
    results: Sequence[tuple[Mapping[str, object], str, Mapping]],
) -> pd.DataFrame:
    """One row per combination and subject: the swept values, ``subject``, the accuracy summary
    and :data:`REFUSED`.

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
        rec[REFUSED] = accuracy.get(REFUSED) or np.nan  # NA: not refused
        records.append(rec)
    table = pd.DataFrame.from_records(records)
    return table[[c for c in table.columns if c != REFUSED] + [REFUSED]]


def _metrics(table: pd.DataFrame, params: Sequence[str]) -> list[str]:
    """The accuracy metrics among a summary's columns (not the swept keys, ``subject`` or
    :data:`~scan2morph.tables.REFUSED`)."""
    return [c for c in table.columns if c not in (*params, "subject", REFUSED)]


def plot_sweep(
    table: pd.DataFrame,
    params: Sequence[str],
    path: str | Path,
    defaults: Mapping[str, object] | None = None,
    dpi: int = 100,
) -> None:
    """Each accuracy metric against the swept key that varied, one panel row per unit.

    Columns of panels are the swept keys, rows the units of the metrics (mm, degrees, fraction,
    px: :func:`scan2morph.tables.accuracy_column`). The panel of key ``k`` shows, per metric
    (colour) and subject (marker), the rows that differ from the config's values ``defaults`` in
    ``k`` only, joined with the config's own row; a dashed vertical line marks the config's
    value of ``k``, a dotted horizontal line per metric and subject the config row's value.
    Rows that differ from the config in two or more keys are left out (the figure says how
    many).

    Parameters
    ----------
    table : DataFrame
        :func:`sweep_summary`.
    params : sequence of str
        The swept keys (columns of ``table``).
    path : str or Path
        PNG written.
    defaults : mapping key -> value, optional
        The config's value of each swept key (:func:`config_values`); default: the table's first
        row (the sweep table's convention: the papers' values first).
    """
    metrics = _metrics(table, params)
    if not metrics or not params or table.empty:
        raise InputError("sweep summary", "no accuracy metric or no swept key to plot")
    if defaults is None:
        defaults = {p: table[p].iloc[0] for p in params}
    missing = [p for p in params if p not in defaults]
    if missing:
        raise InputError("sweep summary", f"no default (config) value for {missing}")
    default, varied = one_at_a_time(table, params, defaults)
    units, by_unit, colour = _units(table, metrics)
    subjects = list(dict.fromkeys(table["subject"]))
    style = {
        s: (_MARKERS[i % len(_MARKERS)], _LINES[i % len(_LINES)]) for i, s in enumerate(subjects)
    }
    plot = _SweepPlot(table, defaults, default, varied, units, by_unit, colour, subjects, style)
    # no pyplot: no global state
    fig = Figure(figsize=(3.6 * len(params) + 3.4, 2.9 * len(units) + 0.6), layout="constrained")
    axes = fig.subplots(len(units), len(params), squeeze=False)
    for j, param in enumerate(params):
        _draw_column(plot, axes[:, j], param, first=j == 0, last=j == len(params) - 1)
    _finish(fig, plot)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with writing(path):
        fig.savefig(path, dpi=dpi, facecolor="white")


def write_sweep_summary(
    results: Sequence[tuple[Mapping[str, object], str, Mapping]],
    params: Sequence[str],
    table_path: str | Path,
    plot_path: str | Path,
    defaults: Mapping[str, object] | None = None,
) -> pd.DataFrame:
    """Write :func:`sweep_summary` as TSV (with its column dictionary on top) and
    :func:`plot_sweep` as PNG; returns the table.

    ``defaults``: the config's value of each swept key (:func:`config_values`); see
    :func:`plot_sweep`.
    """
    if not results:
        raise InputError("sweep summary", "no sweep results to summarise")
    table = sweep_summary(results)
    metrics = _metrics(table, params)
    # each swept value as its combination's folder spells it (``mask_radius_mm~20.0``: the
    # table's float format would write 20)
    spelt = table.assign(**{p: [str(row[p]) for row, _, _ in results] for p in params})
    write_table(table_path, spelt, sweep_dictionary(params, metrics, defaults))
    plot_sweep(table, params, plot_path, defaults)
    return table


@dataclass(frozen=True)
class _SweepPlot:
    """What every panel of :func:`plot_sweep` draws from."""

    table: pd.DataFrame
    defaults: Mapping[str, object]
    default: np.ndarray
    varied: Mapping[str, np.ndarray]
    units: list[str]
    by_unit: dict[str, list[str]]
    colour: dict[str, str]
    subjects: list[str]
    style: dict[str, tuple[str, str]]


def _units(table: pd.DataFrame, metrics) -> tuple[list[str], dict[str, list[str]], dict]:
    """The units of the metrics with data (one panel row each, in :data:`UNIT_LABELS` order),
    the metrics of each, and a colour per metric within its row."""
    by_unit: dict[str, list[str]] = {}
    for m in metrics:
        if table[m].notna().any():
            by_unit.setdefault(accuracy_column(m).unit, []).append(m)
    order = {u: i for i, u in enumerate(UNIT_LABELS)}
    units = sorted(by_unit, key=lambda u: (order.get(u, len(order)), u))
    colour = {m: f"C{i % 10}" for ms in by_unit.values() for i, m in enumerate(ms)}
    return units, by_unit, colour


def _positions(values) -> tuple[dict, bool, list[str]]:
    """The x position of each swept value: the value itself when all are numbers, else its
    index among the categories (returned too)."""
    if all(_number(v) for v in values):
        return {v: float(v) for v in values}, True, []
    cats = list(dict.fromkeys(str(v) for v in values))
    return {v: float(cats.index(str(v))) for v in values}, False, cats


def _draw_column(plot: _SweepPlot, axes, param: str, first: bool, last: bool) -> None:
    """The panels of one swept key, a row per unit (the legends beside the last column)."""
    table, defaults = plot.table, plot.defaults
    rows = table[plot.default | plot.varied[param]]
    values = list(dict.fromkeys([*table[param], defaults[param]]))
    pos, numeric, cats = _positions(values)
    for i, unit in enumerate(plot.units):
        ax = axes[i]
        ax.axvline(pos[defaults[param]], color="0.45", ls="--", lw=1.0, zorder=0)
        for subject in plot.subjects:
            mine = rows[rows["subject"] == subject]
            xs = np.array([pos[v] for v in mine[param]], dtype=float)
            k = np.argsort(xs, kind="stable")
            base = table[plot.default & (table["subject"] == subject).to_numpy()]
            marker, line = plot.style[subject]
            for metric in plot.by_unit[unit]:
                ys = mine[metric].to_numpy(dtype=float)[k]
                ax.plot(xs[k], ys, marker=marker, ls=line, color=plot.colour[metric], ms=4)
                if len(base):
                    ref = float(base[metric].iloc[0])
                    ax.axhline(ref, color=plot.colour[metric], ls=":", lw=0.8, alpha=0.7)
        if not numeric:
            ax.set_xticks(range(len(cats)), cats)
        elif all(float(v).is_integer() for v in values):  # a single value: its tick alone
            ax.xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
        if i == 0:
            n = int(plot.varied[param].sum() // max(len(plot.subjects), 1))
            other = f"{n} other value{'s' if n != 1 else ''}"
            ax.set_title(f"{param} varied ({other})", fontsize="medium")
        if i == len(plot.units) - 1:
            ax.set_xlabel(f"{param} (grey dashed: the config's {defaults[param]})")
        if first:
            ax.set_ylabel(UNIT_LABELS.get(unit, unit))
        ax.margins(x=0.08)  # the config's value is often at an end
        ax.grid(alpha=0.3)
    if last:
        for i, unit in enumerate(plot.units):
            metrics = plot.by_unit[unit]
            handles = [Line2D([], [], color=plot.colour[m], marker="o", ms=4) for m in metrics]
            axes[i].legend(
                handles,
                metrics,
                fontsize="small",
                loc="center left",
                bbox_to_anchor=(1.02, 0.5),
                title=UNIT_LABELS.get(unit, unit),
            )


def _finish(fig: Figure, plot: _SweepPlot) -> None:
    """The subjects' legend, what was left out and the title."""
    notes = []
    subjects, style = plot.subjects, plot.style
    if len(subjects) > 1:
        handles = [
            Line2D([], [], color="0.3", marker=style[s][0], ls=style[s][1]) for s in subjects
        ]
        fig.legend(handles, subjects, loc="outside lower center", ncols=len(subjects))
    elif subjects:
        notes.append(f"subject {subjects[0]}")
    drawn = plot.default.sum() + sum(v.sum() for v in plot.varied.values())
    left_out = int(len(plot.table) - drawn)
    if left_out:
        rows = "row differs" if left_out == 1 else "rows differ"
        notes.append(f"{left_out} {rows} from the config in two or more keys (not drawn)")
    if not plot.default.any():
        notes.append("no row equals the config (no reference lines)")
    fig.suptitle(
        "Accuracy against each swept key, one key varied at a time; dotted: the config's row"
        + ("\n" + "; ".join(notes) if notes else ""),
        fontsize="medium",
    )
