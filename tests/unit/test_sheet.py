"""The take sheet: reading, synthetic rows, per-subject problems."""

from __future__ import annotations

import pytest

from scan2morph.errors import InputError
from scan2morph.sheet import (
    input_roles,
    read_sheet,
    subject_problems,
    synthetic_rows,
    take_table,
)

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
