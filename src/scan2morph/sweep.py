"""Parameter sweeps: accuracy against ground truth as a function of config values.

A sweep table (``config/sweeps.tsv``) has one column per swept config key, named by its dotted
path (``smoothing.iterations``, ``mask.radius_mm``, ``template.subdivision_levels``), and one row
per combination. :func:`read_sweep_table` checks it against the config schema before anything
runs. For one combination and one synthetic subject, :func:`rerun_accuracy` re-runs the stages
from the first one that reads a swept key with the changed values, starting from the subject's
store (and its ingest parts for repair): the same stage functions the workflow runs
(:mod:`scan2morph.stages`), then the accuracy stage. Which stage reads which config section
comes from the stage modules (``SECTIONS``), which datasets a stage writes from
:mod:`scan2morph.store.paths`. The summary table and plot are :mod:`scan2morph.report.sweep`'s.
"""

from __future__ import annotations

import copy
import logging
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from jsonschema import Draft202012Validator, validators

from scan2morph.config_schema import INFINITE, RENAMED_KEYS, integral_value, load_schema
from scan2morph.errors import InputError
from scan2morph.evaluate.truth import Truth
from scan2morph.stages import (
    accuracy,
    align,
    consensus,
    fit,
    landmarks,
    motion,
    motion_noise,
    refine,
    repair,
)
from scan2morph.stages.part import Run
from scan2morph.store import paths
from scan2morph.tables import REFUSED

log = logging.getLogger("scan2morph")

#: The stages a sweep can re-run, in pipeline order (the accuracy stage always follows).
_MODULES = {
    "repair": repair,
    "landmarks": landmarks,
    "fit": fit,
    "align": align,
    "refine": refine,
    "consensus": consensus,
    "motion": motion,
    "motion_noise": motion_noise,
}
STAGES = tuple(_MODULES)
#: Config sections a sweep may vary -> the first stage that reads them.
SECTION_STAGE = {
    section: next(s for s, module in _MODULES.items() if section in module.SECTIONS)
    for section in dict.fromkeys(sec for module in _MODULES.values() for sec in module.SECTIONS)
}

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


#: A cell's spellings of infinity (YAML's and Python's), for a key whose schema allows it.
_INFINITIES = {".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf}


def _parse_value(text: str):
    """A cell's text as int, float, bool or str (YAML-like, but 1e-3 is a float; ``.inf`` as
    YAML writes infinity)."""
    if text.lower() in _INFINITIES:
        return _INFINITIES[text.lower()]
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


def _column_check(schema: Mapping, column: str, source: str):
    """The validator of a sweep table's column (a dotted config path), or a clear error: a key
    that moved, names nothing, sits outside the sweepable sections or is not a scalar."""
    section = column.split(".")[0]
    if column in RENAMED_KEYS:
        raise InputError(source, f"column {column!r}: renamed to {RENAMED_KEYS[column]}")
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
    return _strict_validator(sub)


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
        schema = load_schema(schema)
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
    checks = {column: _column_check(schema, column, source) for column in columns}
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
            sub = checks[column].schema
            # as the config takes them: an integral float at an integer key is the integer
            # (10.0, 1e1), and an infinity only where the key says what it means (.inf: no limit)
            value = integral_value(_parse_value(cell), sub)
            infinite = isinstance(value, float) and not math.isfinite(value)
            if infinite and (value != value or not sub.get(INFINITE)):
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


def check_sweep_rows(table: SweepTable, config: Mapping) -> None:
    """Check each combination's settings as a config's are checked when a run loads
    (:func:`~scan2morph.stages.stage_job.check_stage_params` on the config with the
    combination set), so that a combination whose settings contradict each other (a swept
    ``refine.jaw.start`` above the config's ``end``) stops the run at its start, naming it,
    instead of giving a result row that says the stages refused the subject.

    Raises
    ------
    InputError
        Naming the table, the combination (its number and values) and the config's own line.
    """
    from scan2morph.stages.stage_job import check_stage_params

    for number, row in enumerate(table.rows, start=1):
        try:
            check_stage_params(dict(config) | sweep_settings(config, row))
        except InputError as exc:
            values = ", ".join(f"{k} = {v}" for k, v in row.items())
            raise InputError(table.source, f"combination {number} ({values}): {exc}") from exc


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


def read_store(path: str | Path) -> dict:
    """A subject's store as a sweep re-runs it: its datasets, and each take's refine group
    attributes (a mapping under :func:`scan2morph.store.paths.refine_group`: whether its texture
    correlated, or its shape refined it), which the takes' consensus and the click-noise draws
    read."""
    import h5py

    from scan2morph.store import read_group_attrs, read_part

    with h5py.File(path, "r") as h5:
        takes = list(h5[paths.TAKES]) if paths.TAKES in h5 else []
    return read_part(path) | read_group_attrs(dict.fromkeys(takes, path), paths.refine_group)


def rerun_accuracy(
    store: Mapping[str, np.ndarray],
    run: Run,
    truths: Mapping[str, Truth],
    start: str,
    raw: Mapping[str, np.ndarray] | None = None,
) -> dict:
    """Re-run the stages from ``start`` with a run's settings and measure the accuracy.

    The subject's store provides everything upstream of ``start``; the datasets that ``start``
    and every later stage write (:func:`scan2morph.store.paths.written_by`, including morph and
    modal, which a sweep does not re-run: nothing stale is measured) are dropped, the stages'
    ``apply`` functions recompute theirs in memory, and the accuracy stage measures the result.

    Parameters
    ----------
    store : mapping store path -> array
        The subject's store (:func:`read_store`: its datasets and its refine groups'
        attributes, which a start at ``consensus`` needs).
    run : Run
        The subject, the base template and the config sections with the combination's values
        (:func:`sweep_settings`).
    truths : mapping take -> Truth
        Ground truth of every take.
    start : str
        One of :data:`STAGES`.
    raw : mapping store path -> array, optional
        The ingest parts' datasets of every take; needed when ``start`` is ``repair``.

    Returns
    -------
    dict
        As ``accuracy.json`` (:func:`scan2morph.stages.accuracy.run`).

    Raises
    ------
    InputError
        Unknown stage, a missing dataset, or any stage's own bad-input error.
    """
    source = run.subject.name
    if start not in STAGES:
        raise InputError(source, f"start stage: expected one of {STAGES}, got {start!r}")
    refined = any(k.endswith("/refine/vertices") for k in store)
    verdicts = any(isinstance(v, Mapping) for v in store.values())
    if start == "consensus" and refined and not verdicts:
        raise InputError(
            source,
            "start stage consensus: the store's refine verdicts are missing (read the store "
            "with scan2morph.sweep.read_store)",
        )
    step = paths.STAGES.index(start)
    drop = paths.written_by(paths.STAGES[step:])
    data = {k: v for k, v in store.items() if not drop.match(k)}
    data |= dict(raw or {})
    for name in STAGES[STAGES.index(start) :]:
        data |= _MODULES[name].apply(data, run)
    data |= accuracy.truth_datasets(truths)
    params = accuracy.Params.from_config(run.config)
    return accuracy.run(run.template, run.subject, data, params).files["accuracy"]


def combination_accuracy(*args, **kwargs) -> dict:
    """:func:`rerun_accuracy`, or, when a stage refuses the subject with the combination's
    values (a stricter fit that leaves the neutral out), ``{"summary": {}, "refused": why}``:
    the combination's row of the summary then has no metrics and says why, and the other
    combinations are still summarised (the same arguments as :func:`rerun_accuracy`)."""
    try:
        return rerun_accuracy(*args, **kwargs)
    except InputError as exc:
        log.warning("the combination is refused: %s", exc)
        return {"summary": {}, REFUSED: str(exc)}
