"""A stereo take's texture shot: the left camera's view with the rig's pattern off (the sheet's
``color``), the take's colour instead of the speckled left image; and its bad input.

The synthetic rig renders the same take twice, with its speckle and without
(``speckle_contrast`` 0): the same head, pose and sensor, so the second left image is that
take's texture shot. The real head's measurement (a projected speckle that does not move with
the skin, ``benchmarks/bench_real_user.py``) is in ``tests/workflow/test_real_user.py``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.io import read_stereo_take, write_color
from scan2morph.io.check import take_file_problems
from scan2morph.io.take import MIN_TEXTURE_SHOT_CORRELATION, check_texture_shot
from scan2morph.sheet import COLUMNS, input_roles
from scan2morph.stages import ingest
from scan2morph.stages.part import Take
from scan2morph.store import paths
from tests.support.configs import repo_config
from tests.support.stereo_takes import SMALL_RIG, neutral, write_take

CONFIG = repo_config()


def _take(tmp_path_factory, params: dict, name: str):
    """The neutral of subject s1 written as a user brings it, with its texture shot beside."""
    d = tmp_path_factory.mktemp(name)
    res, shot = neutral(params), neutral(params, speckle_contrast=0.0)
    files = write_take(res, d / "neutral")
    files["color"] = d / "neutral_color.png"
    write_color(files["color"], shot["left"])
    return res, shot, files


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    return _take(tmp_path_factory, SMALL_RIG, "small")


def _ingest(files: dict):
    """The ingest stage of the take's files (the sheet's columns -> paths): its part, and the
    columns its row gives the stage."""
    row = dict.fromkeys(COLUMNS, "") | {"subject": "s1", "take": "neutral", "kind": "neutral"}
    row |= {"label": "neutral", "modality": "stereo"} | {r: str(p) for r, p in files.items()}
    given = {r: row[r] for r in input_roles(row)}
    part = ingest.run(None, Take.from_row(row, files=given), ingest.Params.from_config(CONFIG))
    return part, given


def test_the_texture_shot_is_the_takes_colour_and_its_depth_is_the_pairs(small):
    """With the sheet's ``color`` the take's colour is the texture shot, pixel for pixel, and
    the store says so; the reconstruction is the pair's, the same with or without it."""
    res, shot, files = small
    without = {r: p for r, p in files.items() if r not in ("color", "truth")}
    plain, roles = _ingest(without)
    assert "color" not in roles
    shot_part, roles = _ingest(without | {"color": files["color"]})
    assert roles["color"] == str(files["color"])
    color = shot_part.datasets[paths.raw("neutral", "color")]
    np.testing.assert_array_equal(color, shot["left"])
    np.testing.assert_array_equal(plain.datasets[paths.raw("neutral", "color")], res["left"])
    # the speckle is gone from the colour: the texture shot is not the left image
    assert np.abs(color.astype(int) - res["left"]).mean() > 2.0
    xyz = [p.datasets[paths.raw("neutral", "xyz")] for p in (plain, shot_part)]
    np.testing.assert_array_equal(*xyz)
    source = shot_part.datasets[paths.camera("neutral", "color_source")]
    assert source == ingest.TEXTURE_SHOT
    assert paths.camera("neutral", "color_source") not in plain.datasets  # the store as before
    attrs = shot_part.attrs[paths.take("neutral")]
    assert len(attrs["input_sha256_color"]) == 64


def test_the_stored_stereo_report_holds_no_wall_clock_timings(small):
    """The take's ``stereo`` attribute (the reconstruction's report, copied into the store) is
    the same in any two runs: its timings stay in the log."""
    without = {r: p for r, p in small[2].items() if r not in ("color", "truth")}
    reports = [_ingest(without)[0].attrs[paths.take("neutral")]["stereo"] for _ in range(2)]
    assert "timings_s" not in reports[0] and reports[0]["coverage"] > 0.1
    assert json.dumps(reports[0], sort_keys=True) == json.dumps(reports[1], sort_keys=True)


def _only_its_own_shot_correlates(res: dict, shot: dict) -> None:
    """The band-passed correlation (:func:`check_texture_shot`) accepts the take's own texture
    shot and refuses the right camera's view and the mirrored shot."""
    check_texture_shot(shot["left"], res["left"], "shot.png", "left.png")
    for wrong in (shot["right"], np.ascontiguousarray(shot["left"][:, ::-1])):
        with pytest.raises(InputError, match=r"shot.png: color: the image correlates with"):
            check_texture_shot(wrong, res["left"], "shot.png", "left.png")


def test_only_its_own_texture_shot_correlates_with_a_left_image(small):
    _only_its_own_shot_correlates(*small[:2])


@pytest.mark.slow
def test_only_its_own_texture_shot_correlates_at_640x480(tmp_path_factory):
    _only_its_own_shot_correlates(*_take(tmp_path_factory, {}, "full")[:2])


# --- bad input ------------------------------------------------------------------------------


def test_a_texture_shot_of_another_size_is_refused_naming_it(small, tmp_path):
    res, shot, files = small
    other = tmp_path / "shot.png"
    write_color(other, shot["left"][:100])
    with pytest.raises(
        InputError,
        match=r"shot.png: color: image is 160x100 \(WxH\) but the left image neutral_left.png "
        r"is 160x120",
    ):
        read_stereo_take(files["left"], files["right"], files["calibration"], None, other)


def test_the_right_cameras_shot_is_refused_by_the_subject_check(small, tmp_path):
    """The subject's check (before any job) names the file, the field and what was expected."""
    res, shot, files = small
    right = tmp_path / "right_shot.png"
    write_color(right, shot["right"])
    given = {r: files[r] for r in ("left", "right", "calibration", "landmarks")}
    assert take_file_problems("stereo", given | {"color": files["color"]}) == []
    (problem,) = take_file_problems("stereo", given | {"color": right})
    assert problem.startswith(f"{right}: color: the image correlates with the left image")
    assert f"at least {MIN_TEXTURE_SHOT_CORRELATION:g} expected" in problem
    missing = tmp_path / "none.png"
    (problem,) = take_file_problems("stereo", given | {"color": missing})
    assert problem.startswith(f"{missing}: ") and "not found" in problem
