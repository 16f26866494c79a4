"""Parameter sweeps: accuracy against ground truth as a function of config values.

A sweep table (``config/sweeps.tsv``) has one column per swept config key, named by its dotted
path (``smoothing.iterations``, ``mask.radius_mm``, ``template.subdivision_levels``), and one row
per combination. :func:`read_sweep_table` checks it against the config schema before anything
runs. For one combination and one synthetic subject, :func:`rerun_accuracy` re-runs the stages
from the first one that reads a swept key (repair, fit, align or motion) with the changed values,
starting from the subject's store (and its ingest parts for repair), and measures the result
against the ground truth exactly as the pipeline's accuracy stage does. :func:`write_sweep_summary` collects the combinations into a
table and a plot of each accuracy metric against each swept key.
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from jsonschema import Draft202012Validator, validators
from matplotlib.figure import Figure

from scan2morph.align import align_take, transform_points
from scan2morph.errors import InputError
from scan2morph.evaluate.subject import subject_accuracy
from scan2morph.evaluate.truth import Truth
from scan2morph.motion.model import AlignedMesh, expression_displacements, viseme_motion
from scan2morph.motion.uncertainty import subject_motion_noise
from scan2morph.scan import repair_range
from scan2morph.template import Template, fit_options, fit_take, subdivide_template
from scan2morph.template.datasets import template_datasets
from scan2morph.template.regions import icp_region, named_indices

#: Stages a sweep re-runs, in pipeline order (accuracy always follows).
STAGES = ("repair", "fit", "align", "motion")
#: Config sections a sweep may vary -> the first stage that reads them.
SECTION_STAGE = {
    "repair": "repair",
    "template": "fit",
    "align": "align",
    "mask": "motion",
    "smoothing": "motion",
    "motion_noise": "motion",
}
#: Store datasets each stage writes (regular expressions over store paths), for the stages a
#: sweep re-runs; a sweep drops those of its first stage and after, and recomputes them.
STAGE_DATASETS = {
    "repair": r"^/takes/[^/]+/range/(xyz|spikes|filled)$",
    "fit": r"^/takes/[^/]+/mesh/|^/template/",
    "align": r"^/takes/[^/]+/align/",
    "motion": r"^/(mask|neutral|visemes|motion_noise)/|^/expressions/[^/]+/displacement$",
}
#: Store datasets of the stages after motion (morph, modal), which a sweep does not re-run (the
#: accuracy does not read them): always dropped, so nothing stale is measured.
DOWNSTREAM_DATASETS = r"^/(pca|blends|pca_blends|modal)/|^/expressions/"
#: JSON Schema types a swept value may have (a value becomes part of a folder name).
_SCALAR_TYPES = {"integer", "number", "string", "boolean"}
_SAFE_STRING = re.compile(r"^[A-Za-z0-9_.+-]+$")


def _strict_validator(schema: dict):
    """A Draft 2020-12 validator whose ``integer`` excludes floats (JSON Schema lets 30.0 pass,
    but a float iteration count breaks the stage that reads it)."""
    checker = Draft202012Validator.TYPE_CHECKER.redefine(
        "integer", lambda _, value: isinstance(value, int) and not isinstance(value, bool)
    )
    return validators.extend(Draft202012Validator, type_checker=checker)(schema)


@dataclass(frozen=True)
class SweepTable:
    """A checked sweep table.

    Attributes
    ----------
    source : str
        The file read.
    columns : tuple of str
        Dotted config paths, in file order.
    rows : tuple of dict
        One per combination: column -> value (Python ``int``, ``float``, ``bool`` or ``str``).
    """

    source: str
    columns: tuple[str, ...]
    rows: tuple[dict[str, object], ...]

    @property
    def folder_names(self) -> dict[str, str]:
        """Column -> its name in result folders: the dotted path with ``.`` replaced by ``_``
        (``smoothing.iterations`` -> ``smoothing_iterations``), a Python identifier."""
        return {c: folder_name(c) for c in self.columns}

    def frame(self) -> pd.DataFrame:
        """The rows as a DataFrame of Python objects, columns named by :attr:`folder_names`.

        For ``snakemake.utils.Paramspace``, which names folders ``{column}~{value}`` and reads
        rows as named tuples (so columns must be identifiers).
        """
        frame = pd.DataFrame(list(self.rows), columns=list(self.columns), dtype=object)
        return frame.rename(columns=self.folder_names)

    @property
    def first_stage(self) -> str | None:
        """The earliest stage reading a swept key (None for an empty table)."""
        return first_stage(self.columns) if self.columns else None


def folder_name(column: str) -> str:
    """A swept column's name in result folders (see :attr:`SweepTable.folder_names`)."""
    return column.replace(".", "_")


def first_stage(columns: Sequence[str]) -> str:
    """The earliest of :data:`STAGES` that reads one of the dotted config paths ``columns``."""
    return min((SECTION_STAGE[c.split(".")[0]] for c in columns), key=STAGES.index)


def _subschema(schema: dict, column: str, source: str) -> dict:
    node = schema
    parts = column.split(".")
    for depth, part in enumerate(parts):
        props = node.get("properties", {}) if isinstance(node, dict) else {}
        if part not in props:
            where = ".".join(parts[:depth]) or "the top level"
            known = ", ".join(sorted(props)) or "none"
            raise InputError(
                source,
                f"column {column!r}: names no config key (no {part!r} under {where}; "
                f"keys there: {known})",
            )
        node = props[part]
    return node


def _parse_value(text: str):
    """A cell's text as int, float, bool or str (YAML-like, but 1e-3 is a float)."""
    for convert in (int, float):
        try:
            value = convert(text)
        except ValueError:
            continue
        return value
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    return text


def read_sweep_table(path: str | Path, schema: Mapping | str | Path) -> SweepTable:
    """Read and check a sweep table.

    The file is tab-separated; blank lines and lines starting with ``#`` are skipped, the first
    other line is the header. Each column names a config key by its dotted path, in a section a
    sweep can re-run (:data:`SECTION_STAGE`), whose schema type is a scalar; each cell must be
    valid for that key's schema (type, bounds, enum).

    Parameters
    ----------
    path : str or Path
        The table (``config/sweeps.tsv``).
    schema : mapping, str or Path
        The config JSON Schema (``schemas/config.schema.yaml``) or its file.

    Returns
    -------
    SweepTable

    Raises
    ------
    InputError
        Missing file; a column that names no config key, sits outside the sweepable sections or
        is not a scalar; a ragged or repeated row; a value of the wrong type or out of range;
        a string value that cannot be part of a folder name.
    """
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise InputError(source, "sweep table not found")
    if not isinstance(schema, Mapping):
        with open(schema, encoding="utf-8") as fh:
            schema = yaml.safe_load(fh)
    lines = [
        (n, line.rstrip("\r\n"))
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        return SweepTable(source, (), ())
    columns = tuple(c.strip() for c in lines[0][1].split("\t"))
    if len(set(columns)) != len(columns):
        raise InputError(source, f"header: repeated column in {list(columns)}")
    folders = [folder_name(c) for c in columns]
    if len(set(folders)) != len(folders):
        raise InputError(
            source, f"header: columns {list(columns)} give the same folder names {folders}"
        )
    checks = {}
    for column in columns:
        section = column.split(".")[0]
        sub = _subschema(dict(schema), column, source)
        if section not in SECTION_STAGE:
            raise InputError(
                source,
                f"column {column!r}: a sweep re-runs the stages from repair to accuracy, so it "
                f"can vary keys of {sorted(SECTION_STAGE)}, not of {section!r}",
            )
        types = sub.get("type")
        types = {types} if isinstance(types, str) else set(types or ())
        if not types or not types <= _SCALAR_TYPES:
            raise InputError(
                source,
                f"column {column!r}: a swept key must hold a scalar, this one is {sorted(types) or 'untyped'}",
            )
        checks[column] = _strict_validator(sub)
    rows: list[dict[str, object]] = []
    seen: dict[tuple, int] = {}
    for n, line in lines[1:]:
        cells = [c.strip() for c in line.split("\t")]
        if len(cells) != len(columns):
            raise InputError(
                source, f"line {n}: {len(cells)} fields, expected {len(columns)} (one per column)"
            )
        row = {}
        for column, cell in zip(columns, cells, strict=True):
            where = f"line {n}, column {column!r}"
            if not cell:
                raise InputError(source, f"{where}: empty value")
            value = _parse_value(cell)
            if isinstance(value, float) and not math.isfinite(value):
                raise InputError(source, f"{where}: {cell!r} is not a finite number")
            error = next(iter(checks[column].iter_errors(value)), None)
            if error is not None:
                raise InputError(
                    source,
                    f"{where}: {error.message} (schemas/config.schema.yaml: {column} is "
                    f"{checks[column].schema.get('type')}: {checks[column].schema.get('description', '')})",
                )
            if isinstance(value, str) and not _SAFE_STRING.match(value):
                raise InputError(
                    source, f"{where}: {cell!r}: expected letters, digits and . _ + - only"
                )
            row[column] = value
        key = tuple(row.values())
        if key in seen:
            raise InputError(source, f"line {n}: repeats the combination of line {seen[key]}")
        seen[key] = n
        rows.append(row)
    return SweepTable(source, columns, tuple(rows))


def sweep_settings(config: Mapping, row: Mapping[str, object]) -> dict[str, dict]:
    """The config sections a sweep reads (:data:`SECTION_STAGE`) with one combination set.

    Parameters
    ----------
    config : mapping
        The run's (validated) config.
    row : mapping
        Dotted config path -> value.

    Returns
    -------
    dict
        Section name -> a deep copy of the section with the row's values in place.
    """
    settings = {s: copy.deepcopy(dict(config.get(s, {}))) for s in SECTION_STAGE}
    for column, value in row.items():
        *parents, leaf = column.split(".")
        node = settings
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value.item() if isinstance(value, np.generic) else value
    return settings


def _single_neutral(kinds: Mapping[str, str], source: str) -> str:
    neutral = [t for t, k in kinds.items() if k == "neutral"]
    if len(neutral) != 1:
        raise InputError(source, f"takes: expected exactly one neutral take, got {neutral}")
    return neutral[0]


def rerun_accuracy(
    store: Mapping[str, np.ndarray],
    settings: Mapping[str, Mapping],
    template: Template,
    kinds: Mapping[str, str],
    truths: Mapping[str, Truth],
    start: str,
    source: str,
    raw: Mapping[str, np.ndarray] | None = None,
) -> dict:
    """Re-run the stages from ``start`` with changed settings and measure the accuracy.

    The subject's store provides everything upstream of ``start``; the datasets of ``start`` and
    later stages (:data:`STAGE_DATASETS`, :data:`DOWNSTREAM_DATASETS`) are dropped and the
    stages recomputed in memory, as the pipeline's rules do, then measured as the pipeline's
    accuracy stage does.

    Parameters
    ----------
    store : mapping store path -> array
        The subject's store (``read_part(results/{subject}/{subject}.h5)``).
    settings : mapping
        :func:`sweep_settings`: the sections ``repair``, ``template``, ``align``, ``mask``,
        ``smoothing`` and ``motion_noise`` (the click-noise error bar is recomputed as the
        pipeline does; without the section it is left out).
    template : Template
        The base template (``resources/template.npz``).
    kinds : mapping take -> kind
        Every take of the subject (``neutral``, ``viseme``, ``expression``).
    truths : mapping take -> Truth
        Ground truth of every take.
    start : str
        One of :data:`STAGES`.
    source : str
        The subject (and combination), for messages.
    raw : mapping store path -> array, optional
        ``/takes/{take}/raw/xyz`` of every take (the ingest parts); needed when ``start`` is
        ``repair``.

    Returns
    -------
    dict
        As ``accuracy.json``: :func:`scan2morph.evaluate.subject.subject_accuracy`.

    Raises
    ------
    InputError
        Unknown stage, a missing dataset, or any stage's own bad-input error.
    """
    if start not in STAGES:
        raise InputError(source, f"start stage: expected one of {STAGES}, got {start!r}")
    step = STAGES.index(start)
    drop = re.compile("|".join([*(STAGE_DATASETS[s] for s in STAGES[step:]), DOWNSTREAM_DATASETS]))
    data = {k: v for k, v in store.items() if not drop.search(k)}
    data |= dict(raw or {})
    neutral = _single_neutral(kinds, source)
    visemes = [t for t, k in kinds.items() if k == "viseme"]
    expressions = [t for t, k in kinds.items() if k == "expression"]
    tpl = settings["template"]
    levels = int(tpl["subdivision_levels"])
    fiducials = {t: tpl["fiducials"].get(k, "closed") for t, k in kinds.items()}
    fine = subdivide_template(template, levels)

    def need(key: str) -> np.ndarray:
        if key not in data:
            raise InputError(
                source, f"{key}: missing (expected from the store or the ingest parts)"
            )
        return data[key]

    if step <= STAGES.index("fit"):
        data |= template_datasets(fine)
    for take in kinds:
        g = f"/takes/{take}"
        if step <= STAGES.index("repair"):
            xyz, report = repair_range(
                need(f"{g}/raw/xyz"), dict(settings["repair"]), source=f"{source}/{take}"
            )
            # stored as float32, as the repair stage writes it
            data[f"{g}/range/xyz"] = xyz.astype(np.float32)
            data[f"{g}/range/spikes"], data[f"{g}/range/filled"] = (
                report["spikes"],
                report["filled"],
            )
        if step <= STAGES.index("fit"):
            xyz = need(f"{g}/range/xyz")
            mesh = fit_take(
                template,
                need(f"{g}/landmarks"),
                xyz,
                image_size=(xyz.shape[1], xyz.shape[0]),
                fiducial_set=fiducials[take],
                source=f"{source}/{take}",
                **fit_options(tpl),
            )
            data |= {f"{g}/mesh/{k}": mesh[k] for k in ("vertices", "uv", "valid", "points2d")}
    if step <= STAGES.index("align"):
        al = settings["align"]
        pairs = named_indices(fine, al["point_pairs"], "align.point_pairs")
        icp = np.flatnonzero(icp_region(fine, al["icp_region"]))
        icp_settings = {k: v for k, v in al.items() if k not in ("point_pairs", "icp_region")}
        dst = need(f"/takes/{neutral}/mesh/vertices"), need(f"/takes/{neutral}/mesh/valid")
        for take in kinds:
            g = f"/takes/{take}"
            src, valid = need(f"{g}/mesh/vertices"), need(f"{g}/mesh/valid")
            if take == neutral:
                transform = np.eye(4)
            else:
                transform = align_take(
                    src,
                    valid,
                    *dst,
                    fine.faces,
                    pairs,
                    icp,
                    icp_settings,
                    source=f"{source}/{take}",
                ).transform
            data[f"{g}/align/transform"] = transform
            data[f"{g}/align/vertices"] = transform_points(transform, src)

    def aligned(take: str) -> AlignedMesh:
        return AlignedMesh(need(f"/takes/{take}/align/vertices"), need(f"/takes/{take}/mesh/valid"))

    data |= viseme_motion(
        aligned(neutral),
        {t: aligned(t) for t in visemes},
        fine.faces,
        named_indices(fine, settings["mask"]["paths"], "mask.paths"),
        settings["mask"]["radius_mm"],
        settings["smoothing"]["w"],
        settings["smoothing"]["iterations"],
        source=source,
    )
    data |= expression_displacements(
        aligned(neutral), {t: aligned(t) for t in expressions}, fine.faces, source=source
    )
    if "motion_noise" in settings:
        data |= subject_motion_noise(
            template,
            data,
            neutral,
            visemes,
            fiducials,
            settings["smoothing"],
            fit_options(tpl),
            settings["motion_noise"],
            source=source,
        )[0]
    return subject_accuracy(
        data,
        truths,
        neutral,
        visemes,
        template=template,
        fiducial_sets=fiducials,
        levels=levels,
        smoothing=settings["smoothing"],
        max_slope_deg=tpl["max_slope_deg"],
    )


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
