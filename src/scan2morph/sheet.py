"""The take sheet: one row per take (README, "Running on your own scans"; docs/inputs.md).

The sheet is read one way (pandas, tab-separated, all strings, ``#`` comments at the start of a
line or a cell: :mod:`scan2morph.sheet_text`), its relative paths are resolved against the
sheet's folder, and the synthetic cohort's rows are added from the config.
Problems that belong to one subject (a missing file, an unknown modality, a duplicate take, no
neutral take) do not stop the whole run: :func:`subject_problems` lists them so that only that
subject's jobs fail, with a message naming the file and the row.
"""

from __future__ import annotations

import io
import re
from collections.abc import Collection, Mapping
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING

# the config's checks are importable from here as well (``as``: re-exported)
from scan2morph.config_schema import RENAMED_KEYS as RENAMED_KEYS
from scan2morph.config_schema import load_schema, schema_errors
from scan2morph.config_schema import renamed_keys as renamed_keys
from scan2morph.config_schema import validate_config as validate_config
from scan2morph.errors import InputError
from scan2morph.sheet_consistency import shared_scan_problems, take_name_problems
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
#: Columns the reader adds to say where a row came from (for messages): which sheet, which line.
#: Not what the take is: moving the sheet or deleting rows above leaves its results current.
ROW_LOCATION = ("sheet_row", "sheet")
#: The separator of several files in one cell.
PATH_SEPARATOR = ";"
_ID = re.compile(r"^[A-Za-z0-9_-]+$")
#: The longest subject or take id: an id names files and folders (a 256-character one crashed
#: the scheduler with "File name too long").
MAX_ID_LENGTH = 64


def read_sheet(path: str | Path) -> pd.DataFrame:
    """Read a user's take sheet.

    Paths in the sheet that are relative are resolved against the sheet's folder. Empty cells
    become empty strings. A sheet with only comments gives an empty table.

    Raises
    ------
    InputError
        The file is missing (naming its resolved path), a column name is unknown or empty, a
        required column is missing, a quote is not closed, an id has forbidden characters, a
        subject id is one of :data:`RESERVED_SUBJECTS` or differs from another only in capitals
        (these make the sheet unreadable as a whole, so the run stops before any job).
    """
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        where = "" if path.is_absolute() else f" (relative to the working directory {Path.cwd()})"
        raise InputError(
            path, f"sheet not found (config key 'subjects'): no file {path.resolve()}{where}"
        )
    try:
        text = tab_cells(path, sheet_text(path))
        # keep_default_na=False: a cell reads as written ('NA', 'None' or 'null' is an id, a
        # units cell 'NaN' is refused), not as pandas' missing value (an empty cell)
        df = pd.read_csv(
            io.StringIO(text), sep="\t", dtype=str, index_col=False, keep_default_na=False
        )
    except pd.errors.EmptyDataError:
        df = pd.DataFrame(columns=list(COLUMNS))
    except pd.errors.ParserError as exc:  # the text is decoded: sheet_text names bad bytes
        raise InputError(path, _parser_problem(text, exc)) from exc
    # the header is the first line that is not blank (tab_cells leaves a comment line empty)
    first = next((line for line in text.splitlines() if line.strip()), "")
    header = [c.strip() for c in first.split("\t")]
    if twice := sorted({c for c in header if c and header.count(c) > 1}):
        raise InputError(path, f"column {twice[0]!r} appears more than once in the header")
    df.columns = [c.strip() for c in df.columns]
    if problem := column_problem(list(df.columns)):
        raise InputError(path, problem)
    df = df.reindex(columns=list(COLUMNS), fill_value="").fillna("").apply(lambda c: c.str.strip())
    for row, rec in enumerate(df.itertuples(index=False), start=2):
        for col in ("subject", "take"):
            value = getattr(rec, col)
            if not _ID.match(value):
                what = "is not an id (letters, digits, _ and -)"
                raise InputError(path, f"row {row}, column '{col}': {value!r} {what}")
            if len(value) > MAX_ID_LENGTH:
                raise InputError(
                    path,
                    f"row {row}, column '{col}': {value[:24]!r}... has {len(value)} characters "
                    f"(at most {MAX_ID_LENGTH}: an id names files and folders)",
                )
        if rec.subject.lower() in RESERVED_SUBJECTS:
            raise InputError(path, f"row {row}, column 'subject': {reserved_problem(rec.subject)}")
    spelled: dict[str, tuple[str, int]] = {}
    for row, subject in enumerate(df["subject"], start=2):
        first, at = spelled.setdefault(subject.lower(), (subject, row))
        if first != subject:  # results/Alice is results/alice on macOS and Windows
            raise InputError(
                path,
                f"row {row}, column 'subject': {subject!r} differs from {first!r} (row {at}) only "
                f"in capitals, and on a case-insensitive file system (macOS, Windows) both would "
                f"write results/{first}/; spell one subject one way",
            )
    base = path.resolve().parent
    for col in PATH_COLUMNS:
        df[col] = [_resolve(v, base, col in MULTI_PATH_COLUMNS) for v in df[col]]
    df["sheet_row"] = range(2, len(df) + 2)
    df["sheet"] = str(path)
    df["synthetic"] = False
    return df


def column_problem(columns: list[str]) -> str | None:
    """What is wrong with a sheet's column names, in one line, or None.

    A name in other capitals (``Subject``) or close to a known one (``modalty``) is named with
    the column it stands for; other unknown names with the known columns; then the required
    columns still missing (the others may be left out).
    """
    import difflib

    said, known = [], [c for c in columns if c in COLUMNS]
    for name in (c for c in columns if c not in COLUMNS):
        if name.lower() in COLUMNS:
            said.append(f"column {name!r} should be {name.lower()!r} (names are lower case)")
            known.append(name.lower())
        elif close := difflib.get_close_matches(name.lower(), COLUMNS, n=1, cutoff=0.75):
            said.append(f"unknown column {name!r} (did you mean {close[0]!r}?)")
            known.append(close[0])
        else:
            said.append(f"unknown column {name!r} (known: {', '.join(COLUMNS)})")
    if missing := [c for c in REQUIRED if c not in known]:
        said.append(f"required columns {missing} missing")
    return "; ".join(said) or None


def _parser_problem(text: str, exc: Exception) -> str:
    """pandas' complaint about a sheet's text as one line; an unclosed quote names its line
    (pandas names a row of its own count, not the sheet's line)."""
    if "EOF inside string" in str(exc):
        for k, line in enumerate(text.splitlines(), start=1):
            cells = line.split("\t")
            start = next((i for i, c in enumerate(cells) if c.lstrip().startswith('"')), None)
            if start is not None and "\t".join(cells[start:]).count('"') % 2:
                return (
                    f'line {k}: a cell opens a quote (") that is not closed on its line; close '
                    "it or remove the quote"
                )
    return f"not a tab-separated sheet: {' '.join(str(exc).split())}"


#: Folders the workflow writes directly under ``results/`` besides the subjects' own
#: (``results/{subject}/``): a subject of one of these names would write into them (and
#: empty them). Compared in lower case, as a case-insensitive file system does.
RESERVED_SUBJECTS = ("cohort", "synthetic", "sweeps")


def reserved_problem(subject: str, fix: str = "rename the subject") -> str:
    """Why ``subject``, one of :data:`RESERVED_SUBJECTS`, cannot be a subject id."""
    return (
        f"{subject!r} names a folder the workflow writes under results/ (reserved: "
        f"{', '.join(RESERVED_SUBJECTS)}); {fix}"
    )


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


def _check_cohort(takes: list[dict], n_subjects: int, prefix: str) -> None:
    """The takes and ids of :func:`synthetic_rows` (a cohort of at least one subject): one
    neutral, no take id twice (else every synthetic subject stops at its check job), no
    generated id among :data:`RESERVED_SUBJECTS`."""
    if n_subjects < 1:
        return
    source = "config: synthetic.takes"
    if (n := [t.get("kind") for t in takes].count("neutral")) != 1:
        raise InputError(source, f"expected exactly one take of kind 'neutral', found {n}")
    ids = [t.get("take") for t in takes]
    if twice := sorted({t for t in ids if ids.count(t) > 1}):
        raise InputError(source, f"take ids {twice} appear more than once")
    for subject in (f"{prefix}{i:02d}" for i in range(1, n_subjects + 1)):
        if subject.lower() in RESERVED_SUBJECTS:
            raise InputError("config: synthetic.prefix", reserved_problem(subject, "change it"))


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
        integers, or a take is listed twice; ``takes`` has no neutral, or more than one, or a
        take id twice; a subject id is one of :data:`RESERVED_SUBJECTS`.
    """
    import pandas as pd

    switches = {"stereo": stereo or {}, "mesh": mesh or {}, "rgbd": rgbd or {}}
    take_ids = [t["take"] for t in takes]
    _check_cohort(takes, n_subjects, prefix)
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
    return pd.DataFrame(rows, columns=[*COLUMNS, *ROW_LOCATION, "synthetic"])


def sheet_problems(
    table: pd.DataFrame,
    check_files: bool = True,
    schema: str | PathLike[str] | None = None,
    reserved: Collection[str] = (),
) -> dict[str, list[tuple[str, str]]]:
    """The sheet's problems per subject, each with the take it belongs to.

    Checks: kind and modality known, the modality's files named (and present when
    ``check_files``, for user rows), take ids unique per subject (in any capitals), exactly one
    neutral take, no take id that names a model output (:func:`take_name_problems`;
    ``reserved``: the config's blend names), no scan file serving two rows
    (:func:`shared_scan_problems`), and, with ``schema`` (``schemas/sheet.schema.yaml``),
    every user row against it (e.g. an empty ``label``). Each problem is one line naming the
    sheet row and the column.

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
                            what = (
                                f"{part} is a folder, not a file"
                                if Path(part).is_dir()
                                else f"file not found: {part}"
                            )
                            out.append((rec.take, f"{where}: column '{col}': {what}"))
        lower = rows["take"].str.lower()
        for key in lower[lower.duplicated()].unique():
            takes = list(dict.fromkeys(rows["take"][lower == key]))
            said = (
                f"take {takes[0]!r} appears more than once"
                if len(takes) == 1  # else results/{subject}/takes/Car is .../car on macOS
                else f"takes {takes} differ only in capitals (one folder on a case-insensitive "
                "file system)"
            )
            out.append(("", f"{rows['sheet'].iloc[0]}: {said} for subject {subject!r}"))
        # a take of an unknown kind is left out by its kind's line alone (not also named as a
        # non-neutral 'neutral' when its kind is 'Neutral')
        known = rows[rows["kind"].isin(KINDS)]
        out += take_name_problems(known, reserved) + shared_scan_problems(rows)
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


def take_table(sheet: pd.DataFrame, synthetic: pd.DataFrame) -> pd.DataFrame:
    """All takes (user and synthetic), indexed by (subject, take), first row of a duplicate kept."""
    import pandas as pd

    both = pd.concat([sheet, synthetic], ignore_index=True)
    # in any capitals: results/SYNTH01 is results/synth01 on macOS and Windows
    cohort = {s.lower() for s in synthetic["subject"]}
    clash = {s for s in sheet["subject"] if s.lower() in cohort}
    if clash:
        raise InputError(
            sheet["sheet"].iloc[0],
            f"subject ids {sorted(clash)} clash with the synthetic cohort's (ids are compared "
            "in any capitals); rename them or set synthetic.prefix",
        )
    both = both.set_index(["subject", "take"], drop=False)
    return both[~both.index.duplicated(keep="first")]
