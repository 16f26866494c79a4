"""The take sheet: one row per take (README, "Running on your own scans"; docs/inputs.md).

The sheet is read one way (pandas, tab-separated, all strings, ``#`` comments at the start of a
line or a cell: :mod:`scan2morph.sheet_text`), its relative paths are resolved against the
sheet's folder, and the synthetic cohort's rows are added from the config.
Problems that belong to one subject (a missing file, an unknown modality, a duplicate take, no
neutral take) do not stop the whole run: :func:`subject_problems` lists them so that only that
subject's jobs fail, with a message naming the file and the row.
"""

from __future__ import annotations

import copy
import io
import re
from collections.abc import Mapping
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING

from scan2morph.errors import InputError
from scan2morph.sheet_text import sheet_text, tab_cells
from scan2morph.units import unit_scale, units_problem

if TYPE_CHECKING:  # pandas is imported where a table is made: a take's ingest needs none (0.3 s)
    import pandas as pd

COLUMNS = (
    "subject",
    "take",
    "kind",
    "label",
    "modality",
    "xyz",
    "color",
    "left",
    "right",
    "calibration",
    "mesh",
    "texture",
    "depth",
    "intrinsics",
    "landmarks",
    "units",
)
REQUIRED = ("subject", "take", "kind", "label", "modality")
KINDS = ("neutral", "viseme", "expression")
MODALITIES = ("range", "stereo", "mesh", "rgbd")
#: The file columns each modality needs.
FILES = {
    "range": ("xyz",),
    "stereo": ("left", "right", "calibration"),
    "mesh": ("mesh",),
    "rgbd": ("depth", "color", "intrinsics"),
}
#: File columns a modality may have (used when not empty): the landmarks (without them they are
#: detected), a mesh's texture, when the mesh file does not reference one; a range scan's colour
#: image (without it the take is geometry only); a stereo take's texture shot (the left camera's
#: view without the rig's projected pattern; without it the left image is the colour).
OPTIONAL_FILES = {
    "range": ("color", "landmarks"),
    "stereo": ("color", "landmarks"),
    "mesh": ("texture", "landmarks"),
    "rgbd": ("landmarks",),
}
#: Every column that holds a file path (resolved against the sheet's folder).
PATH_COLUMNS = tuple(c for c in COLUMNS if c not in REQUIRED and c != "units")
#: Columns whose cell may name several files separated by ``;`` (or a folder): an RGB-D take's
#: depth frames (:func:`scan2morph.io.depth_image.depth_frame_paths`).
MULTI_PATH_COLUMNS = ("depth",)
#: The separator of several files in one cell.
PATH_SEPARATOR = ";"
_ID = re.compile(r"^[A-Za-z0-9_-]+$")


def read_sheet(path: str | Path) -> pd.DataFrame:
    """Read a user's take sheet.

    Paths in the sheet that are relative are resolved against the sheet's folder. Empty cells
    become empty strings. A sheet with only comments gives an empty table.

    Raises
    ------
    InputError
        The file is missing, a required column is missing or an id has forbidden characters
        (these make the sheet unreadable as a whole, so the run stops before any job).
    """
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "sheet not found (config key 'subjects')")
    try:
        text = tab_cells(path, sheet_text(path))
        df = pd.read_csv(io.StringIO(text), sep="\t", dtype=str, index_col=False)
    except pd.errors.EmptyDataError:
        df = pd.DataFrame(columns=list(COLUMNS))
    except pd.errors.ParserError as exc:  # the text is decoded: sheet_text names bad bytes
        raise InputError(path, f"not a tab-separated sheet: {' '.join(str(exc).split())}") from exc
    df.columns = [c.strip() for c in df.columns]
    missing = [c for c in REQUIRED if c not in df.columns]
    if missing:
        raise InputError(path, f"columns {missing} missing (expected {list(COLUMNS)})")
    unknown = [c for c in df.columns if c not in COLUMNS]
    if unknown:
        raise InputError(path, f"unknown columns {unknown} (expected {list(COLUMNS)})")
    df = df.reindex(columns=list(COLUMNS), fill_value="").fillna("").apply(lambda c: c.str.strip())
    for row, rec in enumerate(df.itertuples(index=False), start=2):
        for col in ("subject", "take"):
            value = getattr(rec, col)
            if not _ID.match(value):
                what = "is not an id (letters, digits, _ and -)"
                raise InputError(path, f"row {row}, column '{col}': {value!r} {what}")
    base = path.resolve().parent
    for col in PATH_COLUMNS:
        df[col] = [_resolve(v, base, col in MULTI_PATH_COLUMNS) for v in df[col]]
    df["sheet_row"] = range(2, len(df) + 2)
    df["sheet"] = str(path)
    df["synthetic"] = False
    return df


def mm_per_unit(row) -> float:
    """A take's coordinate unit in mm from its sheet row's ``units`` (1 when the column is
    empty or absent).

    Raises
    ------
    InputError
        Naming the sheet row and the column: a value other than ``mm``, ``cm``, ``m`` or a
        positive number (:func:`unit_scale`), or a unit for a modality the column does not scale
        (:data:`~scan2morph.units.UNITS_MODALITIES`).
    """
    problem = units_problem(row.get("units", ""), row.get("modality", ""))
    if problem:
        where = (
            f"{row.get('sheet', 'sheet')} row {row.get('sheet_row', '?')} "
            f"({row.get('subject')}/{row.get('take')})"
        )
        raise InputError(where, problem)
    return unit_scale(row.get("units", ""))


def split_paths(value: str) -> list[str]:
    """The paths of a cell of :data:`MULTI_PATH_COLUMNS` (``a.png; b.png``), blanks left out."""
    return [v.strip() for v in str(value).split(PATH_SEPARATOR) if v.strip()]


def _resolve(value: str, base: Path, several: bool) -> str:
    """A cell's path(s) resolved against the sheet's folder ``base`` (``~`` is the home folder,
    as in a shell)."""
    parts = split_paths(value) if several else ([value] if value else [])
    parts = [str(Path(v).expanduser()) if v.startswith("~") else v for v in parts]
    out = [v if Path(v).is_absolute() else str(base / v) for v in parts]
    return f"{PATH_SEPARATOR} ".join(out)


def input_roles(row) -> list[str]:
    """The file columns of a take's row that its ingest reads: its modality's
    :data:`FILES`, then the :data:`OPTIONAL_FILES` that are not empty."""
    modality = row["modality"]
    optional = [c for c in OPTIONAL_FILES.get(modality, ()) if row[c]]
    return [*FILES.get(modality, ()), *optional]


#: Synthetic input files of each modality (besides the landmarks): column -> name pattern.
SYNTHETIC_FILES = {
    "range": {"xyz": "{stem}.abs.gz", "color": "{stem}.png"},
    "stereo": {
        "left": "{stem}_left.png",
        "right": "{stem}_right.png",
        "calibration": "{stem}_calib.yaml",
    },
    "mesh": {"mesh": "{stem}.ply"},
    "rgbd": {
        "depth": "{stem}_depth.png",
        "color": "{stem}.png",
        "intrinsics": "{stem}_intrinsics.yaml",
    },
}


def rgbd_frames(rgbd: Mapping) -> int:
    """Depth frames per synthetic RGB-D take (config ``synthetic.rgbd.sensor.frames``)."""
    return int(rgbd.get("sensor", {}).get("frames", 1))


def synthetic_depth_frames(stem: str, frames: int) -> list[str]:
    """A synthetic RGB-D take's depth files: ``{stem}_depth.png`` (the colour image's frame),
    then ``{stem}_depth_2.png`` ... for a take of several frames."""
    first = SYNTHETIC_FILES["rgbd"]["depth"].format(stem=stem)
    return [first, *(f"{stem}_depth_{k}.png" for k in range(2, frames + 1))]


def _check_switches(switches: Mapping, take_ids: list[str], n_subjects: int) -> None:
    """The modality switches of :func:`synthetic_rows`: subject numbers and known takes."""
    for name, switch in switches.items():
        source = f"config: synthetic.{name}"
        numbers = list(switch.get("subjects", []))
        if any(isinstance(n, bool) or not isinstance(n, int) or n < 1 for n in numbers):
            raise InputError(source, f"subjects: expected 1-based subject numbers, got {numbers}")
        # a switch whose subjects are all beyond a smaller cohort is off: takes not checked
        unknown = [t for t in switch.get("takes", []) if t not in take_ids]
        if unknown and any(n <= n_subjects for n in numbers):
            raise InputError(
                source, f"takes: {unknown} not among synthetic.takes (expected some of {take_ids})"
            )


def _synthetic_files(modality: str, stem: str, frames: int) -> dict[str, str]:
    """A synthetic take's file columns (the landmarks' left empty): :data:`SYNTHETIC_FILES`,
    an RGB-D take's depth frames joined as in a sheet."""
    files = dict.fromkeys(PATH_COLUMNS[:-1], "")
    files |= {c: v.format(stem=stem) for c, v in SYNTHETIC_FILES[modality].items()}
    if modality == "rgbd":
        files["depth"] = f"{PATH_SEPARATOR} ".join(synthetic_depth_frames(stem, frames))
    return files


#: Synthetic landmark file of each modality: 3D points on a mesh, iBUG .pts on an image.
SYNTHETIC_LANDMARKS = {"mesh": "{stem}_landmarks3d.txt"}
#: Modalities a synthetic take may be given for some subjects (config ``synthetic.{modality}``).
SYNTHETIC_SWITCHED = ("stereo", "mesh", "rgbd")


def synthetic_rows(
    n_subjects: int,
    prefix: str,
    takes: list[dict],
    root: str,
    stereo: dict | None = None,
    mesh: dict | None = None,
    rgbd: dict | None = None,
    landmarks: str = "clicked",
) -> pd.DataFrame:
    """Rows of the synthetic cohort, whose files the synthetic rules write under ``root``.

    Parameters
    ----------
    n_subjects : int
        Number of synthetic subjects (ids ``{prefix}01``, ``{prefix}02``, ...).
    prefix : str
        Subject id prefix.
    takes : list of dict
        Each with ``take``, ``kind``, ``label`` and optionally ``modality`` (``range``, the
        default, or ``stereo``: that take is a stereo pair for every subject).
    root : str
        Folder of the synthetic inputs (``results/synthetic``).
    stereo : dict, optional
        ``subjects`` (1-based subject numbers) and ``takes`` (take ids of ``takes``): those
        takes of those subjects are stereo pairs too. Numbers above ``n_subjects`` are
        ignored (so that a smaller cohort keeps the same config); other keys are ignored.
    mesh, rgbd : dict, optional
        The same for textured mesh scans and RGB-D takes. A take listed for a subject under
        two modalities is an error.
    landmarks : ``clicked`` or ``detect``
        ``detect``: the rows' ``landmarks`` empty (the generator's clicks are not read).

    Returns
    -------
    pandas.DataFrame
        One row per take with the sheet's columns, the files of :data:`SYNTHETIC_FILES`
        (``{stem}`` = ``{root}/{subject}/{take}``): a range take has ``xyz``
        (``{take}.abs.gz``) and ``color`` (``{take}.png``), a stereo take ``left``
        (``{take}_left.png``), ``right`` (``{take}_right.png``) and ``calibration``
        (``{take}_calib.yaml``), a mesh take ``mesh`` (``{take}.obj``, with its MTL and
        texture), an RGB-D take ``depth`` (``{take}_depth.png``), ``color`` and
        ``intrinsics`` (``{take}_intrinsics.yaml``); all have ``landmarks`` (``{take}.pts``,
        for a mesh take ``{take}_landmarks3d.txt``) unless ``landmarks`` is ``detect``.

    Raises
    ------
    InputError
        ``{modality}.takes`` names a take that is not in ``takes`` (for a switch with a
        subject in the cohort), ``{modality}.subjects`` holds something other than positive
        integers, or a take is listed twice.
    """
    import pandas as pd

    switches = {"stereo": stereo or {}, "mesh": mesh or {}, "rgbd": rgbd or {}}
    take_ids = [t["take"] for t in takes]
    _check_switches(switches, take_ids, n_subjects)
    rows = []
    for i in range(1, n_subjects + 1):
        subject = f"{prefix}{i:02d}"
        for t in takes:
            stem = f"{root}/{subject}/{t['take']}"
            listed = [
                name
                for name, switch in switches.items()
                if i in switch.get("subjects", []) and t["take"] in switch.get("takes", [])
            ]
            if len(listed) > 1:
                raise InputError(
                    f"config: synthetic.{listed[1]}",
                    f"take {t['take']!r} of subject {i} is also listed under synthetic.{listed[0]}",
                )
            modality = listed[0] if listed else t.get("modality", "range")
            files = _synthetic_files(modality, stem, rgbd_frames(switches["rgbd"]))
            pattern = SYNTHETIC_LANDMARKS.get(modality, "{stem}.pts")
            rows.append(
                dict(
                    subject=subject,
                    take=t["take"],
                    kind=t["kind"],
                    label=t["label"],
                    modality=modality,
                    **files,
                    landmarks=pattern.format(stem=stem) if landmarks == "clicked" else "",
                    units="",
                    sheet_row=0,
                    sheet="config: synthetic",
                    synthetic=True,
                )
            )
    return pd.DataFrame(rows, columns=[*COLUMNS, "sheet_row", "sheet", "synthetic"])


def sheet_problems(
    table: pd.DataFrame,
    check_files: bool = True,
    schema: str | PathLike[str] | None = None,
) -> dict[str, list[tuple[str, str]]]:
    """The sheet's problems per subject, each with the take it belongs to.

    Checks: kind and modality known, the modality's files named (and present when
    ``check_files``, for user rows), take ids unique per subject, exactly one neutral take, and,
    with ``schema`` (``schemas/sheet.schema.yaml``), every user row against it (e.g. an empty
    ``label``). Each problem is one line naming the sheet row and the column.

    Returns
    -------
    dict subject -> list of (take, problem)
        ``take`` is empty for a problem of the whole subject (a repeated take id, no or two
        neutral takes): that stops the subject. A take's own problem leaves only that take out
        (unless it is the neutral's).
    """
    problems: dict[str, list[str]] = {}
    table = table.reset_index(drop=True)
    row_schema = load_schema(schema) if schema is not None else None
    for subject, rows in table.groupby("subject", sort=False):
        out = []
        for rec in rows.itertuples(index=False):
            where = f"{rec.sheet} row {rec.sheet_row} ({subject}/{rec.take})"
            if row_schema is not None and not rec.synthetic:
                record = {c: getattr(rec, c) for c in COLUMNS}
                for key, problem in schema_errors(record, row_schema):
                    empty = problem == "empty"
                    if not (empty and key in FILES.get(rec.modality, ())):  # reported below
                        out.append((rec.take, f"{where}: column '{key}': {problem}"))
            if problem := units_problem(rec.units, rec.modality):
                out.append((rec.take, f"{where}: {problem}"))
            if rec.kind not in KINDS:
                out.append(
                    (
                        rec.take,
                        f"{where}: kind {rec.kind!r} unknown (expected one of {list(KINDS)})",
                    )
                )
            if rec.modality not in MODALITIES:
                out.append(
                    (
                        rec.take,
                        f"{where}: modality {rec.modality!r} unknown "
                        f"(expected one of {list(MODALITIES)})",
                    )
                )
                continue
            for col in FILES[rec.modality] + OPTIONAL_FILES.get(rec.modality, ()):
                value = getattr(rec, col)
                if not value:
                    if col in FILES[rec.modality]:
                        out.append(
                            (
                                rec.take,
                                f"{where}: column '{col}' is empty (a {rec.modality} take needs it)",
                            )
                        )
                elif check_files and not rec.synthetic:
                    several = col in MULTI_PATH_COLUMNS
                    for part in split_paths(value) if several else [value]:
                        found = Path(part).is_file() or (several and Path(part).is_dir())
                        if not found:
                            out.append(
                                (rec.take, f"{where}: column '{col}': file not found: {part}")
                            )
        dup = rows["take"][rows["take"].duplicated()].unique()
        for take in dup:
            out.append(
                (
                    "",
                    f"{rows['sheet'].iloc[0]}: take {take!r} appears more than once for subject "
                    f"{subject!r}",
                )
            )
        n_neutral = int((rows["kind"] == "neutral").sum())
        if n_neutral != 1:
            out.append(
                (
                    "",
                    f"subject {subject!r}: expected exactly one take of kind 'neutral', "
                    f"found {n_neutral}",
                )
            )
        problems[subject] = out
    return problems


def subject_problems(
    table: pd.DataFrame,
    check_files: bool = True,
    schema: str | PathLike[str] | None = None,
) -> dict[str, list[str]]:
    """:func:`sheet_problems` without the takes: every problem of each subject, one line each."""
    return {
        subject: [problem for _, problem in problems]
        for subject, problems in sheet_problems(table, check_files, schema).items()
    }


def load_schema(path: str | PathLike[str]) -> dict:
    """A JSON schema from a YAML (or JSON) file (libyaml's parser where PyYAML has it: the
    same document, about ten times faster than the pure-Python one on the config schema)."""
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    with open(path, encoding="utf-8") as fh:
        return yaml.load(fh, Loader=loader)


def schema_errors(data: object, schema: dict) -> list[tuple[str, str]]:
    """Every way ``data`` breaks ``schema`` (JSON Schema draft 2020-12), as short
    ``(key path, problem)`` pairs, shallowest first. ``key path`` is dotted (``a.b[2].c``),
    ``<top>`` for the whole document; the problem never quotes more than 80 characters of
    the value (jsonschema's own messages can hold a whole schema or config section).
    """
    from jsonschema import Draft202012Validator

    validator = Draft202012Validator(schema)
    errors = sorted(
        validator.iter_errors(data), key=lambda e: (len(e.path), list(map(str, e.path)))
    )
    out = []
    for e in errors:
        path = list(e.absolute_path)
        if e.validator == "additionalProperties" and isinstance(e.instance, dict):
            known = e.schema.get("properties", {})
            extra = [k for k in e.instance if k not in known]
            allowed = ", ".join(sorted(known))
            out += [(_key_path([*path, k]), f"unknown key (known: {allowed})") for k in extra]
        else:
            out.append((_key_path(path), _problem(e)))
    return out


#: The ICP settings of ``align.icp`` (before, keys of ``align`` itself).
_ICP_KEYS = (
    "method",
    "max_correspondence_mm",
    "max_iterations",
    "robust_kernel",
    "kernel_k_mm",
    "kernel_noise_sigmas",
    "trim_rounds",
    "trim_radius_mm",
    "trim_sigma",
    "min_fitness",
    "max_rmse_ratio",
    "max_rmse_mm",
    "min_inlier_fraction",
)
_LIP_KEYS = ("prior", "stretch", "min_contrast", "search", "max_shift", "min_share")
#: Config keys that moved (old dotted path -> new): a config or sweep table still naming one
#: is refused with one line naming the new key.
RENAMED_KEYS = {
    **{f"refine.jaw_{k}": f"refine.jaw.{k}" for k in ("prior", "start", "end", "max_rmse_ratio")},
    **{f"refine.lip_{k}": f"refine.lip.{k}" for k in _LIP_KEYS},
    **{f"refine.lower_lip_{k}": f"refine.lower_lip.{k}" for k in ("prior", "shrink")},
    **{f"align.{k}": f"align.icp.{k}" for k in _ICP_KEYS},
}


def renamed_keys(config: Mapping) -> list[str]:
    """The old keys of :data:`RENAMED_KEYS` that ``config`` still uses, each as
    ``"{old}: renamed to {new}"``."""
    found = []
    for old, new in RENAMED_KEYS.items():
        section, key = old.split(".")
        if isinstance(config.get(section), Mapping) and key in config[section]:
            found.append(f"{old}: renamed to {new}")
    return found


def validate_config(config: dict, schema: str | PathLike[str], source: str = "config") -> dict:
    """Check a config against its schema and fill in the schema's defaults, in place.

    Defaults are set as :func:`snakemake.utils.validate` sets them: while validating, every
    property with a ``default`` missing from its object is set to (a copy of) that default,
    and the default's own properties are then checked and filled in turn.

    Raises
    ------
    InputError
        Naming ``source``, the first problem's key path and what is wrong (one line; the number
        of further problems is appended); a key that moved (:data:`RENAMED_KEYS`) is named with
        its new path.
    """
    from jsonschema import Draft202012Validator, validators

    moved = renamed_keys(config)
    if moved:
        raise InputError(source, "; ".join(moved))
    schema_doc = load_schema(schema)
    properties = Draft202012Validator.VALIDATORS["properties"]

    def set_defaults(validator, props, instance, sub):
        if isinstance(instance, dict):
            for name, subschema in props.items():
                if isinstance(subschema, dict) and "default" in subschema:
                    instance.setdefault(name, copy.deepcopy(subschema["default"]))
        yield from properties(validator, props, instance, sub)

    filling = validators.extend(Draft202012Validator, {"properties": set_defaults})
    for _ in filling(schema_doc).iter_errors(config):
        pass  # the errors are reported below, from a plain validator on the filled config
    problems = schema_errors(config, schema_doc)
    if (nan := _nan_path(config)) is not None:  # the schema's 'number' takes it
        problems.insert(0, (_key_path(nan), "expected a number, got nan"))
    if problems:
        key, problem = problems[0]
        more = f" (and {len(problems) - 1} more problems)" if len(problems) > 1 else ""
        raise InputError(source, f"{key}: {problem}{more}")
    return config


def _nan_path(value: object, path: tuple = ()) -> tuple | None:
    """The key path of the first NaN in a config (a number every comparison refuses: a
    threshold of .nan would let everything through, or nothing), None when there is none."""
    if isinstance(value, float) and value != value:
        return path
    items = value.items() if isinstance(value, dict) else ()
    for key, item in enumerate(value) if isinstance(value, list) else items:
        if (found := _nan_path(item, (*path, key))) is not None:
            return found
    return None


def _key_path(path) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top>"


def _short(value: object, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _problem(error) -> str:
    """A short description of a jsonschema ValidationError."""
    kind, arg, value = error.validator, error.validator_value, error.instance
    if kind == "minLength" and value == "":
        return "empty"
    if kind == "required":
        missing = [k for k in arg if isinstance(value, dict) and k not in value]
        return f"missing key {', '.join(repr(k) for k in missing)}"
    if kind == "type":
        return f"expected {arg if isinstance(arg, str) else ' or '.join(arg)}, got {_short(value)}"
    if kind == "enum":
        return f"expected one of {list(arg)}, got {_short(value)}"
    if kind == "pattern":
        return f"{_short(value)} does not match {arg!r}"
    if kind in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        bound = {"minimum": ">=", "maximum": "<=", "exclusiveMinimum": ">"}.get(kind, "<")
        return f"expected a value {bound} {arg}, got {_short(value)}"
    if kind in ("minItems", "maxItems", "minLength", "maxLength"):
        return f"{kind} {arg}: got {_short(value)}"
    message = error.message
    return message if len(message) <= 160 else message[:157] + "..."


def take_table(sheet: pd.DataFrame, synthetic: pd.DataFrame) -> pd.DataFrame:
    """All takes (user and synthetic), indexed by (subject, take), first row of a duplicate kept."""
    import pandas as pd

    both = pd.concat([sheet, synthetic], ignore_index=True)
    clash = set(sheet["subject"]) & set(synthetic["subject"])
    if clash:
        raise InputError(
            sheet["sheet"].iloc[0],
            f"subject ids {sorted(clash)} clash with the synthetic cohort's; rename them or set "
            "synthetic.prefix",
        )
    both = both.set_index(["subject", "take"], drop=False)
    return both[~both.index.duplicated(keep="first")]
