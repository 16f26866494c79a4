"""The take sheet: reading, synthetic rows, per-subject problems."""

from __future__ import annotations

import pytest

from scan2morph.errors import InputError
from scan2morph.sheet import read_sheet, subject_problems, synthetic_rows, take_table

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
    with pytest.raises(InputError, match="clash with the synthetic cohort"):
        sheet = read_sheet(
            _sheet(tmp_path, [["synth01", "n", "neutral", "n", "range", "", "", "", "", "", "p"]])
        )
        take_table(
            sheet, synthetic_rows(1, "synth", [dict(take="n", kind="neutral", label="n")], "r")
        )


def test_comment_only_sheet_is_empty(tmp_path):
    path = tmp_path / "s.tsv"
    path.write_text("# nothing yet\n" + HEADER)
    assert len(read_sheet(path)) == 0
