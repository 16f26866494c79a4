"""The take sheet: reading, synthetic rows, per-subject problems."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from scan2morph import sheet
from scan2morph.errors import InputError
from scan2morph.sheet import (
    RESERVED_SUBJECTS,
    input_roles,
    read_sheet,
    subject_problems,
    synthetic_rows,
    take_table,
)
from tests.support.configs import REPO

HEADER = "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor\tleft\tright\tcalibration\tlandmarks\n"


def _sheet(tmp_path, rows):
    path = tmp_path / "sheet.tsv"
    path.write_text("# a comment\n" + HEADER + "".join("\t".join(r) + "\n" for r in rows))
    return path


def _files(tmp_path, *names):
    for n in names:
        (tmp_path / n).write_text("x")


def test_paths_resolve_against_the_sheet_and_problems_are_per_subject(tmp_path):
    _files(tmp_path, "n.abs", "n.png", "n.pts", "c.abs", "c.png", "c.pts")
    rows = [
        ["ok", "neutral", "neutral", "neutral", "range", "n.abs", "n.png", "", "", "", "n.pts"],
        ["ok", "car", "viseme", "car", "range", "c.abs", "c.png", "", "", "", "c.pts"],
        ["bad", "neutral", "neutral", "neutral", "range", "n.abs", "gone.png", "", "", "", "n.pts"],
        ["bad", "car", "viseme", "car", "laser", "c.abs", "c.png", "", "", "", "c.pts"],
        ["bad", "car", "viseme", "car", "range", "c.abs", "c.png", "", "", "", "c.pts"],
        ["lonely", "car", "viseme", "car", "range", "c.abs", "c.png", "", "", "", "c.pts"],
    ]
    sheet = read_sheet(_sheet(tmp_path, rows))
    assert sheet.loc[0, "xyz"] == str(tmp_path / "n.abs")
    problems = subject_problems(sheet)
    assert problems["ok"] == []
    text = "\n".join(problems["bad"])
    assert "row 4 (bad/neutral): column 'color': file not found" in text and "gone.png" in text
    assert "row 5 (bad/car): modality 'laser' unknown" in text
    assert "take 'car' appears more than once for subject 'bad'" in text
    assert problems["lonely"] == [
        "subject 'lonely': expected exactly one take of kind 'neutral', found 0"
    ]
    table = take_table(
        sheet,
        synthetic_rows(1, "synth", [dict(take="neutral", kind="neutral", label="neutral")], "r"),
    )
    assert list(table.loc["synth01", "xyz"]) == ["r/synth01/neutral.abs.gz"]
    assert len(table.loc["bad"]) == 2  # the duplicate is dropped from the DAG, reported above


def test_bad_sheets_stop_the_run(tmp_path):
    with pytest.raises(InputError, match="sheet not found"):
        read_sheet(tmp_path / "none.tsv")
    path = tmp_path / "s.tsv"
    path.write_text("subject\ttake\n")
    with pytest.raises(InputError, match="columns .*'kind'.* missing"):
        read_sheet(path)
    path.write_text(HEADER + "a b\tneutral\tneutral\tn\trange\tx\ty\t\t\t\tz\n")
    with pytest.raises(InputError, match="row 2, column 'subject': 'a b' is not an id"):
        read_sheet(path)
    cohort = synthetic_rows(1, "synth", [dict(take="n", kind="neutral", label="n")], "r")
    # in any capitals: results/SYNTH01 is results/synth01 on a case-insensitive file system
    for subject in ("synth01", "SYNTH01"):
        row = [subject, "n", "neutral", "n", "range", "", "", "", "", "", "p"]
        with pytest.raises(InputError, match=rf"\['{subject}'\] clash with the synthetic cohort"):
            take_table(read_sheet(_sheet(tmp_path, [row])), cohort)


def test_comment_only_sheet_is_empty(tmp_path):
    path = tmp_path / "s.tsv"
    path.write_text("# nothing yet\n" + HEADER)
    assert len(read_sheet(path)) == 0


def test_mesh_and_rgbd_rows(tmp_path):
    """The new columns: a mesh take needs mesh and landmarks (texture optional, checked when
    given), an RGB-D take depth, color, intrinsics and landmarks."""
    _files(tmp_path, "m.obj", "m.txt", "d.png", "c.png", "i.yaml", "c.pts")
    path = tmp_path / "sheet.tsv"
    cols = (
        "subject\ttake\tkind\tlabel\tmodality\tmesh\ttexture\tdepth\tcolor\tintrinsics\tlandmarks\n"
    )
    rows = [
        ["m", "neutral", "neutral", "neutral", "mesh", "m.obj", "", "", "", "", "m.txt"],
        ["t", "neutral", "neutral", "neutral", "mesh", "m.obj", "gone.png", "", "", "", "m.txt"],
        ["r", "neutral", "neutral", "neutral", "rgbd", "", "", "d.png", "c.png", "i.yaml", "c.pts"],
        ["q", "neutral", "neutral", "neutral", "rgbd", "", "", "d.png", "c.png", "", "c.pts"],
    ]
    path.write_text(cols + "".join("\t".join(r) + "\n" for r in rows))
    sheet = read_sheet(path)
    assert sheet.loc[0, "mesh"] == str(tmp_path / "m.obj")
    problems = subject_problems(sheet)
    assert problems["m"] == [] and problems["r"] == []
    assert problems["t"] == [
        f"{path} row 3 (t/neutral): column 'texture': file not found: {tmp_path / 'gone.png'}"
    ]
    assert problems["q"] == [
        f"{path} row 5 (q/neutral): column 'intrinsics' is empty (a rgbd take needs it)"
    ]
    assert input_roles(sheet.loc[0]) == ["mesh", "landmarks"]
    assert input_roles(sheet.loc[1]) == ["mesh", "texture", "landmarks"]


def test_synthetic_mesh_and_rgbd_takes():
    takes = [
        dict(take="neutral", kind="neutral", label="neutral"),
        dict(take="car", kind="viseme", label="car"),
    ]
    rows = synthetic_rows(
        3, "s", takes, "r", mesh=dict(subjects=[1], takes=["neutral", "car"]),
        rgbd=dict(subjects=[2, 7], takes=["car"]),
    )  # fmt: skip
    by = rows.set_index(["subject", "take"])
    assert by.loc[("s01", "car"), "modality"] == "mesh"
    assert by.loc[("s01", "car"), "mesh"] == "r/s01/car.ply"
    assert by.loc[("s01", "car"), "landmarks"] == "r/s01/car_landmarks3d.txt"
    assert by.loc[("s02", "neutral"), "modality"] == "range"
    rgbd = by.loc[("s02", "car")]
    assert (rgbd["modality"], rgbd["depth"], rgbd["color"], rgbd["intrinsics"]) == (
        "rgbd", "r/s02/car_depth.png", "r/s02/car.png", "r/s02/car_intrinsics.yaml"
    )  # fmt: skip
    assert rgbd["landmarks"] == "r/s02/car.pts" and rgbd["xyz"] == ""
    # the default switches (subjects 3 and 4, every default take) stay quiet in a smaller cohort
    # with takes of its own, and speak up when they apply
    small = synthetic_rows(2, "s", takes, "r", mesh=dict(subjects=[3], takes=["car", "sad2"]))
    assert set(small["modality"]) == {"range"}
    with pytest.raises(InputError, match=r"synthetic.mesh: takes: \['sad2'\] not among"):
        synthetic_rows(3, "s", takes, "r", mesh=dict(subjects=[3], takes=["car", "sad2"]))
    with pytest.raises(InputError, match="synthetic.rgbd: take 'car' of subject 1 is also listed"):
        synthetic_rows(1, "s", takes, "r", mesh=dict(subjects=[1], takes=["car"]),
                       rgbd=dict(subjects=[1], takes=["car"]))  # fmt: skip


# --- bad sheets: one line naming the sheet and what was expected ---
ROWS = "a\tneutral\tneutral\tneutral\trange\tn.abs\tn.png\t\t\t\tn.pts\n"


def _read_error(path, text) -> str:
    path.write_text(text)
    with pytest.raises(InputError) as exc:
        read_sheet(path)
    assert "\n" not in str(exc.value)
    return str(exc.value)


def test_header_mistakes_name_the_column_meant(tmp_path):
    """Before: a trailing tab gave "unknown columns ['Unnamed: 11']", ``Subject`` "columns
    ['subject'] missing" and ``modalty`` "columns ['modality'] missing" with all 16 columns."""
    path = tmp_path / "s.tsv"
    assert _read_error(path, HEADER.replace("\n", "\t\n") + ROWS) == (
        f"{path}: header (line 1): column 12 has no name (a tab at the end of the header line?); "
        "remove the tab"
    )
    assert "column 3 has no name (two tabs in a row" in _read_error(
        path, HEADER.replace("kind", "\tkind") + ROWS
    )
    assert _read_error(path, "Subject" + HEADER[7:] + ROWS) == (
        f"{path}: column 'Subject' should be 'subject' (names are lower case)"
    )
    assert _read_error(path, HEADER.replace("modality", "modalty") + ROWS) == (
        f"{path}: unknown column 'modalty' (did you mean 'modality'?)"
    )
    assert _read_error(path, "subject\ttake\tmesh\n") == (
        f"{path}: required columns ['kind', 'label', 'modality'] missing"
    )
    assert "unknown column 'scan' (known: subject, take," in _read_error(
        path, HEADER.replace("xyz", "scan") + ROWS
    )


def test_an_unclosed_quote_names_the_sheet_line(tmp_path):
    """Before: pandas' 'EOF inside string starting at row 2', a row of its own count."""
    path = tmp_path / "s.tsv"
    text = "# comment\n" + HEADER + ROWS + ROWS.replace("a\tneutral", 'b\t"neutral')
    assert _read_error(path, text) == (
        f'{path}: line 4: a cell opens a quote (") that is not closed on its line; close it or '
        "remove the quote"
    )
    path.write_text(HEADER + ROWS.replace("n.abs", '"n.abs"'))  # a closed quote is read
    assert read_sheet(path).loc[0, "xyz"] == str(tmp_path / "n.abs")


@pytest.mark.parametrize("subject", ["cohort", "synthetic", "sweeps", "Cohort"])
def test_a_subject_named_as_a_workflow_folder_is_refused(tmp_path, subject):
    """Before: accepted, and the subject wrote into (and emptied) results/{subject}/."""
    path = tmp_path / "s.tsv"
    message = _read_error(path, HEADER + ROWS + ROWS.replace("a\t", f"{subject}\t", 1))
    assert message == (
        f"{path}: row 3, column 'subject': {subject!r} names a folder the workflow writes under "
        "results/ (reserved: cohort, synthetic, sweeps); rename the subject"
    )


def test_the_reserved_ids_are_the_folders_the_rules_write_under_results():
    rules = [*(REPO / "workflow" / "rules").glob("*.smk"), REPO / "Snakefile"]
    text = "\n".join(p.read_text() for p in rules)
    folders = set(re.findall(r"results/([A-Za-z0-9_-]+)", text))  # not results/{subject}
    assert folders == set(RESERVED_SUBJECTS)


def test_a_synthetic_prefix_making_a_reserved_id_is_refused(monkeypatch):
    """No reserved name ends in digits today, so no prefix reaches one; the check is on the
    ids the cohort makes, should a folder name ending in digits be added."""
    monkeypatch.setattr(sheet, "RESERVED_SUBJECTS", (*RESERVED_SUBJECTS, "runs02"))
    takes = [dict(take="n", kind="neutral", label="n")]
    assert len(synthetic_rows(1, "runs", takes, "r")) == 1
    with pytest.raises(InputError, match=r"^config: synthetic\.prefix: 'runs02' names a folder"):
        synthetic_rows(2, "runs", takes, "r")


@pytest.mark.parametrize(
    "takes, match",
    [
        ([("car", "viseme")], "expected exactly one take of kind 'neutral', found 0"),
        ([("n", "neutral"), ("m", "neutral")], "expected exactly one take of kind 'neutral', found 2"),
        ([("n", "neutral"), ("car", "viseme"), ("car", "viseme")], r"take ids \['car'\] appear more than once"),
    ],
)  # fmt: skip
def test_synthetic_takes_that_would_stop_every_subject_are_one_config_line(takes, match):
    """Before: accepted at load, then every synthetic subject stopped at its check job."""
    takes = [dict(take=t, kind=k, label=t) for t, k in takes]
    with pytest.raises(InputError, match=f"^config: synthetic.takes: {match}$"):
        synthetic_rows(2, "s", takes, "r")
    assert len(synthetic_rows(0, "s", takes, "r")) == 0  # no cohort: nothing stops


def test_a_missing_sheet_names_its_resolved_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError) as exc:
        read_sheet("my/subjects.tsv")
    assert str(exc.value) == (
        "my/subjects.tsv: sheet not found (config key 'subjects'): no file "
        f"{tmp_path.resolve() / 'my' / 'subjects.tsv'} (relative to the working directory "
        f"{Path.cwd()})"
    )


def test_the_example_rows_of_the_default_sheet_read_under_its_header(tmp_path):
    """config/subjects.tsv, which the README points to for the columns: its commented example
    rows, uncommented under its header, are a sheet of every modality."""
    lines = (REPO / "config" / "subjects.tsv").read_text().splitlines()
    header = next(line for line in lines if line and not line.startswith("#"))
    rows = [line[1:] for line in lines if line.startswith("#") and "\t" in line]
    assert rows[0] == header  # the commented header is the real one
    (tmp_path / "s.tsv").write_text("\n".join([header, *rows[1:]]) + "\n")
    sheet = read_sheet(tmp_path / "s.tsv")
    assert set(sheet["modality"]) == {"range", "stereo", "mesh", "rgbd"}


def test_a_scan_file_serving_two_takes_of_a_subject_leaves_the_later_out(tmp_path):
    """A cell copied from another row (the bad-input audit's F1: another take's colour image of
    the same size was taken without a word, and the refinement followed it tens of mm off): the
    later take is left out, naming the earlier row. Two subjects may share scans (the same
    scans run twice to compare landmarks), and landmark files may be copied."""
    _files(tmp_path, "n.abs", "n.png", "n.pts", "c.abs", "c.png", "s.abs")
    rows = [
        ["a", "neutral", "neutral", "neutral", "range", "n.abs", "n.png", "", "", "", "n.pts"],
        ["a", "car", "viseme", "car", "range", "c.abs", "c.png", "", "", "", "n.pts"],
        ["a", "smile1", "expression", "smile", "range", "s.abs", "c.png", "", "", "", ""],
        ["b", "neutral", "neutral", "neutral", "range", "n.abs", "n.png", "", "", "", ""],
        ["b", "car", "viseme", "car", "range", "n.abs", "c.png", "", "", "", ""],
    ]
    path = _sheet(tmp_path, rows)
    problems = sheet.sheet_problems(read_sheet(path))
    assert problems["a"] == [
        (
            "smile1",
            f"{path} row 4 (a/smile1): column 'color': {tmp_path / 'c.png'} is also the color of "
            "row 3 (car): each take needs its own scan (a cell copied from another row?)",
        )
    ]
    assert [(t, p.split(": ")[1]) for t, p in problems["b"]] == [("car", "column 'xyz'")]


@pytest.mark.parametrize("take", ["neutral", "pca_mean", "pca_2_neg", "car_30"])
def test_a_take_named_as_a_model_of_its_subject_is_left_out(tmp_path, take):
    """The bad-input audit's F3: a viseme take called 'neutral', 'car_30' (a blend of the
    config) or 'pca_mean' had its model OBJ or glTF target overwritten without a word."""
    _files(tmp_path, "n.abs", "c.abs")
    rows = [
        ["s", "n0", "neutral", "neutral", "range", "n.abs", "", "", "", "", ""],
        ["s", take, "viseme", "car", "range", "c.abs", "", "", "", "", ""],
    ]
    problems = sheet.sheet_problems(read_sheet(_sheet(tmp_path, rows)), reserved=["car_30"])
    ((name, problem),) = problems["s"]
    assert name == take and f"take id {take!r} is also the name of " in problem
    assert problem.endswith(
        "(meshes/models/" + take + ".obj, the glTF's morph target); rename the take"
    )
    # the neutral itself may be called 'neutral'
    rows[0][1] = "neutral"
    rows[1][1] = "car"
    assert sheet.sheet_problems(read_sheet(_sheet(tmp_path, rows)))["s"] == []


def test_a_capitalised_kind_is_not_told_to_rename_its_take(tmp_path):
    """Before: kind 'Neutral' gave its own line and a misleading one: "take id 'neutral' is
    also the name of a model of the subject's own ...; rename the take" (audit finding 16).
    What is left: the kind's line and the subject's missing neutral."""
    _files(tmp_path, "n.abs", "c.abs")
    rows = [
        ["s", "neutral", "Neutral", "neutral", "range", "n.abs", "", "", "", "", ""],
        ["s", "car", "viseme", "car", "range", "c.abs", "", "", "", "", ""],
    ]
    problems = sheet.sheet_problems(read_sheet(_sheet(tmp_path, rows)))["s"]
    assert [(t, p.split(": ", 1)[1]) for t, p in problems] == [
        ("neutral", "kind 'Neutral' unknown (expected one of ['neutral', 'viseme', 'expression'])"),
        ("", "expected exactly one take of kind 'neutral', found 0"),
    ]


def test_header_ids_and_cells_the_bad_input_audit_found_misleading(tmp_path):
    """A column given twice was "unknown column 'color.1'"; a 256-character take id crashed the
    scheduler; a folder in a file column was "file not found"; MM and Cm were unknown units."""
    _files(tmp_path, "n.abs", "c.abs")
    (tmp_path / "scans").mkdir()
    twice = tmp_path / "twice.tsv"
    for comment in ("", "# a comment first\n\n"):  # the header after comments and blank lines
        twice.write_text(comment + HEADER.replace("\tcolor\t", "\tcolor\tcolor\t"))
        with pytest.raises(InputError, match=r"twice.tsv: column 'color' appears more than once"):
            read_sheet(twice)
    rows = [
        ["s", "neutral", "neutral", "neutral", "range", "n.abs", "", "", "", "", ""],
        ["s", "x" * 256, "viseme", "car", "range", "c.abs", "", "", "", "", ""],
    ]
    with pytest.raises(InputError, match=r"row 3, column 'take': 'xxx.*'... has 256 characters"):
        read_sheet(_sheet(tmp_path, rows))
    rows[1][1], rows[1][5] = "car", "scans"
    problems = subject_problems(read_sheet(_sheet(tmp_path, rows)))["s"]
    assert problems == [
        f"{tmp_path / 'sheet.tsv'} row 3 (s/car): column 'xyz': {tmp_path / 'scans'} is a folder, "
        "not a file"
    ]
    from scan2morph.units import unit_scale

    assert [unit_scale(u) for u in ("MM", "Cm", "M", "mm", "furlongs")] == [
        1.0,
        10.0,
        1000.0,
        1.0,
        None,
    ]


def test_cells_pandas_takes_for_missing_values_read_as_written(tmp_path):
    """A subject 'NA' (initials) or a take 'null' was read as an empty cell, and the whole
    sheet refused as "'' is not an id"; a units cell 'NaN' or 'N/A' was silently mm."""
    _files(tmp_path, "n.abs", "c.abs")
    rows = [
        ["NA", "neutral", "neutral", "neutral", "range", "n.abs", "", "", "", "", ""],
        ["NA", "null", "viseme", "None", "range", "c.abs", "", "", "", "", ""],
    ]
    table = read_sheet(_sheet(tmp_path, rows))
    assert table[["subject", "take", "label"]].values.tolist() == [
        ["NA", "neutral", "neutral"],
        ["NA", "null", "None"],
    ]
    path = tmp_path / "units.tsv"
    path.write_text(HEADER.replace("\n", "\tunits\n") + "\t".join(rows[0]) + "\tNaN\n")
    problems = subject_problems(read_sheet(path))["NA"]
    assert problems == [
        f"{path} row 2 (NA/neutral): column 'units': 'NaN' unknown (expected mm, "
        "cm, m or a number of mm per unit, e.g. 25.4 for inches; empty means mm)"
    ]


def test_ids_that_differ_only_in_capitals_are_refused(tmp_path):
    """'alice' and 'Alice' ran as two subjects and 'car' and 'Car' as two takes: on macOS or
    Windows each pair writes one folder (results/alice/, results/alice/takes/car/), and one
    subject's or take's results overwrote the other's."""
    _files(tmp_path, "n.abs", "c.abs", "d.abs")
    rows = [
        ["alice", "neutral", "neutral", "neutral", "range", "n.abs", "", "", "", "", ""],
        ["alice", "car", "viseme", "car", "range", "c.abs", "", "", "", "", ""],
        ["alice", "Car", "viseme", "car", "range", "d.abs", "", "", "", "", ""],
    ]
    problems = subject_problems(read_sheet(_sheet(tmp_path, rows)))["alice"]
    assert problems == [
        f"{tmp_path / 'sheet.tsv'}: takes ['car', 'Car'] differ only in capitals (one folder on "
        "a case-insensitive file system) for subject 'alice'"
    ]
    rows[2][:2] = ["Alice", "neutral"]
    with pytest.raises(InputError) as exc:
        read_sheet(_sheet(tmp_path, rows))
    assert str(exc.value) == (
        f"{tmp_path / 'sheet.tsv'}: row 4, column 'subject': 'Alice' differs from 'alice' (row 2) "
        "only in capitals, and on a case-insensitive file system (macOS, Windows) both would "
        "write results/alice/; spell one subject one way"
    )
