"""Bad input, wider (issue #14 part 4): every case works or fails its subject with one clear line.

Library level: the readers, :func:`scan2morph.stages.ingest.run` and :func:`fit_take` on small
synthetic takes written as a user would bring them.
"""

from __future__ import annotations

import copy
import errno
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from scan2morph.errors import InputError, OutputError
from scan2morph.io import (
    read_abs,
    read_color,
    read_range,
    read_range_take,
    read_stereo_calibration,
    write_abs,
    write_color,
    write_npz_range,
    write_pts,
    write_stereo_calibration,
)
from scan2morph.io.rgbd import read_rgbd_intrinsics
from scan2morph.sheet import read_sheet, subject_problems, validate_config
from scan2morph.stages import Take, ingest
from scan2morph.stages import fit as fit_stage
from scan2morph.stages.stage_job import check_stage_params
from scan2morph.synth import make_stereo_take, make_take, write_stereo_take, write_take
from scan2morph.template import build_template, fit_take
from scan2morph.template.sample import SCANNER_FRAME, scanner_view
from tests.support.configs import repo_config
from tests.support.workflow_api import snakemake_dry_run

ROOT = Path(__file__).resolve().parents[2]
TINY = dict(width=160, height=120, focal_px=362.5, distance_mm=1000.0)
TINY_RIG = dict(width=160, height=120, focal_px=325.0)
ROW = dict(subject="s1", take="neutral", kind="neutral", label="neutral", modality="range")


def _run_ingest(row, files, mesh_camera=None):
    """The ingest stage on one take's files (no stereo settings)."""
    params = ingest.Params(mesh_camera=mesh_camera or {})
    return ingest.run(None, Take.from_row(row, files=files), params)


HEADER = "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor\tleft\tright\tcalibration\tlandmarks\n"


@pytest.fixture(scope="module")
def take():
    return make_take("s1", "neutral", "neutral", "neutral", seed=3, params=dict(TINY))


@pytest.fixture(scope="module")
def stereo():
    return make_stereo_take("s1", "neutral", "neutral", "neutral", seed=3, params=dict(TINY_RIG))


@pytest.fixture(scope="module")
def template():
    return build_template()


def _write(tmp_path, take, xyz=None, landmarks=None, name="t"):
    res = dict(take)
    if xyz is not None:
        res["xyz"] = xyz
    if landmarks is not None:
        res["landmarks"] = landmarks
    files = {
        "xyz": tmp_path / f"{name}.abs.gz",
        "color": tmp_path / f"{name}.png",
        "landmarks": tmp_path / f"{name}.pts",
    }
    write_take(res, files["xyz"], files["color"], files["landmarks"], tmp_path / f"{name}.npz")
    return files


def _ingest(files, modality="range"):
    return _run_ingest(dict(ROW, modality=modality), {k: str(v) for k, v in files.items()})


def _one_line(exc: pytest.ExceptionInfo, source) -> str:
    text = str(exc.value)
    assert "\n" not in text and text.startswith(str(source))
    return text


def test_a_good_take_passes_the_face_checks(tmp_path, take):
    part = _ingest(_write(tmp_path, take))
    assert part is not None


# --- degenerate landmarks -------------------------------------------------------------------


def _all_equal(lm):
    return np.tile(lm[30], (68, 1))


def _mirrored(lm):
    return np.column_stack([TINY["width"] - 1 - lm[:, 0], lm[:, 1]])


@pytest.mark.parametrize(
    "change, at_ingest, at_fit",
    [
        (_all_equal, "landmarks: all 68 points coincide", "the image points all coincide"),
        (_mirrored, "landmarks: mirrored left/right", "landmarks fold the template"),
    ],
)
def test_degenerate_landmarks(tmp_path, take, template, change, at_ingest, at_fit):
    landmarks = change(take["landmarks"])
    files = _write(tmp_path, take, landmarks=landmarks)
    with pytest.raises(InputError, match=at_ingest) as exc:
        _ingest(files)
    _one_line(exc, files["landmarks"])
    with pytest.raises(InputError, match=at_fit):
        fit_take(template, landmarks, take["xyz"], source="s1/neutral")


def test_landmarks_with_x_and_y_swapped_say_so(tmp_path, take):
    """A .pts written (row, column) instead of (x, y) mirrors the face about its diagonal: it
    was refused as 'mirrored left/right' alone (audit finding 17); the message now asks whether
    x and y are swapped, and a face mirrored left/right is not asked that."""
    lm = take["landmarks"]
    centre = lm.mean(axis=0)
    swapped = centre + (lm - centre)[:, ::-1]  # about the face's centre: it stays on the face
    files = _write(tmp_path, take, landmarks=swapped)
    with pytest.raises(InputError) as exc:
        _ingest(files)
    text = _one_line(exc, files["landmarks"])
    assert "mirrored left/right" in text
    assert text.endswith("are the file's x and y swapped? (x is the column, y the row)")
    files = _write(tmp_path, take, landmarks=_mirrored(lm), name="m")
    with pytest.raises(InputError, match="mirrored left/right") as exc:
        _ingest(files)
    assert "swapped" not in str(exc.value)


def test_landmarks_on_the_background(tmp_path, take, template):
    lm = take["landmarks"]
    corner = (lm - lm.min(axis=0)) * 0.25 + 1.0  # a small face in the top-left corner
    assert np.isnan(take["xyz"][:15, :15]).all()
    files = _write(tmp_path, take, landmarks=corner)
    with pytest.raises(InputError, match="iBUG 37 at .* lies where the range image has no data"):
        _ingest(files)
    with pytest.raises(InputError, match="fall on range data"):
        fit_take(template, corner, take["xyz"], source="s1/neutral")


def test_landmarks_outside_the_image_or_nan(tmp_path, take):
    lm = take["landmarks"].copy()
    lm[36] = [200.0, 50.0]
    files = _write(tmp_path, take, landmarks=lm)
    with pytest.raises(InputError, match="point 37 lies outside the 160x120 image") as exc:
        _ingest(files)
    _one_line(exc, files["landmarks"])
    text = files["landmarks"].read_text().splitlines()
    text[3 + 36] = "nan 50.0"
    files["landmarks"].write_text("\n".join(text) + "\n")
    with pytest.raises(InputError, match="point 37: non-finite coordinate"):
        _ingest(files)


# --- implausible scale ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "factor, match",
    [
        (
            1e-3,
            r"are 0\.09\d+ mm apart in 3D, expected 50-150 mm \(the coordinates look like metres",
        ),
        (0.1, r"are 9\.\d+ mm apart .* \(the coordinates look like cm"),
        (3.0, r"are 28\d(\.\d)? mm apart .* \(a face 2\.\d times the usual size\)"),
    ],
)
def test_a_subject_in_metres_or_a_head_too_large(tmp_path, take, factor, match):
    files = _write(tmp_path, take, xyz=take["xyz"] * factor)
    with pytest.raises(
        InputError, match=r"face size: the outer eye corners \(iBUG 37, 46\) " + match
    ) as exc:
        _ingest(files)
    _one_line(exc, files["xyz"])


def test_the_subject_check_scales_a_range_take_by_its_units_column(tmp_path, take):
    """The subject's check reads a range take in the sheet's unit as the ingest does: a scan in
    metres with ``units: m`` passes, and a scan in mm given ``units: m`` is refused naming the
    column (before, the check ignored the column both ways)."""
    from scan2morph.io.check import take_file_problems

    in_m = {k: str(v) for k, v in _write(tmp_path, take, xyz=take["xyz"] / 1000.0).items()}
    assert take_file_problems("range", in_m, 1000.0) == []
    assert _run_ingest(dict(ROW, units="m"), in_m) is not None
    in_mm = {k: str(v) for k, v in _write(tmp_path, take, name="mm").items()}
    (problem,) = take_file_problems("range", in_mm, 1000.0)
    assert problem.startswith(in_mm["xyz"]) and "\n" not in problem
    assert "the sheet's units column scaled the xyz by 1000 mm per unit" in problem
    (problem,) = take_file_problems("range", in_m)
    assert "look like metres" in problem and "the sheet's units column" in problem
    with pytest.raises(InputError, match="units column scaled the xyz by 1000 mm"):
        _run_ingest(dict(ROW, units="m"), in_mm)


def _stereo_files(tmp_path, stereo, calib=None, swap=False):
    res = dict(stereo)
    if calib is not None:
        res["calib"] = calib
    names = {k: tmp_path / f"n{s}" for k, s in (("left", "_l.png"), ("right", "_r.png"))}
    names |= {"calibration": tmp_path / "n.yaml", "landmarks": tmp_path / "n.pts"}
    write_stereo_take(res, *names.values(), tmp_path / "n.npz")
    if swap:
        names["left"], names["right"] = names["right"], names["left"]
    return names


def test_stereo_calibration_in_cm_or_metres(tmp_path, stereo):
    c = stereo["calib"]
    in_cm = type(c)(c.K1, c.D1, c.K2, c.D2, c.R, c.T / 10.0, c.image_size)
    files = _stereo_files(tmp_path, stereo, in_cm)
    with pytest.raises(
        InputError, match=r"n.yaml may be in cm \(baseline \|T\| = 12\), expected mm$"
    ) as exc:
        _ingest(files, "stereo")
    _one_line(exc, files["left"])
    in_m = type(c)(c.K1, c.D1, c.K2, c.D2, c.R, c.T / 1000.0, c.image_size)
    path = tmp_path / "m.yaml"
    with pytest.raises(InputError, match=r"T: baseline \|T\| = 0\.12\d* is below 1 mm; .*metres"):
        write_stereo_calibration(path, in_m)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML_1_0)
    for name in ("K1", "D1", "K2", "D2", "R", "T"):
        fs.write(name, np.asarray(getattr(in_m, name)))
    fs.release()
    with pytest.raises(InputError, match=r"m.yaml: T: baseline \|T\| = 0\.12\d* .*metres"):
        read_stereo_calibration(path)


def test_swapped_stereo_images_are_named(tmp_path, stereo):
    files = _stereo_files(tmp_path, stereo, swap=True)
    with pytest.raises(InputError, match="left and right may be swapped") as exc:
        _ingest(files, "stereo")
    _one_line(exc, files["left"])
    assert _ingest(_stereo_files(tmp_path, stereo), "stereo") is not None


# --- pose, tiny and empty scans, huge headers ---------------------------------------------------


def test_profile_view(tmp_path, take):
    lm = take["landmarks"].copy()
    cx = lm[30, 0]
    lm[:, 0] = cx + 0.1 * (lm[:, 0] - cx)  # eye corners nearly coincident in the image
    files = _write(tmp_path, take, landmarks=lm)
    with pytest.raises(InputError, match=r"head pose: the outer eye corners .* profile") as exc:
        _ingest(files)
    _one_line(exc, files["landmarks"])


def _board(take, diamond: bool) -> np.ndarray:
    """A flat board where the take's face is: the plane through its points (an affine map of
    the pixel grid, so in its scanner frame and scale), over the whole grid or a diamond (whose
    side corners stuck out of the outline like a nose in profile)."""
    from scan2morph.geometry import affine_fit

    xyz = take["xyz"]
    rows, cols = np.indices(xyz.shape[:2])
    pixels = np.column_stack([cols.ravel(), rows.ravel()]).astype(np.float64)
    ok = np.isfinite(xyz).all(axis=2).ravel()
    board = np.column_stack([pixels, np.ones(len(pixels))]) @ affine_fit(
        pixels[ok], xyz.reshape(-1, 3)[ok]
    )
    board = board.reshape(xyz.shape)
    if diamond:
        h, w = xyz.shape[:2]
        board[np.abs(cols - w / 2) + np.abs(rows - h / 2) > 0.4 * h] = np.nan
    return board


def test_a_flat_scan_is_named_flat_not_a_profile_view(tmp_path, take):
    """A board given as a take (the audit: "a profile view") is refused as flat, naming the take
    or file: by the detector (a diamond-shaped board: its corners stuck out sideways like a nose
    in profile), with clicked landmarks (they went through) and as a mesh."""
    import trimesh

    from scan2morph.landmarks import detect

    flat = r"no face relief: the surface is flat \(\d\.\d mm deep about its best-fitting plane"
    with pytest.raises(InputError, match=r"^s1/board: " + flat) as exc:
        detect(take["color"], _board(take, diamond=True), "s1/board")
    assert "profile" not in str(exc.value) and "no nose-like peak" in str(exc.value)
    files = _write(tmp_path, take, xyz=_board(take, diamond=False))
    with pytest.raises(InputError, match=flat + r".*, though its landmarks mark a face") as exc:
        _ingest(files)
    _one_line(exc, files["xyz"])
    trimesh.creation.box(extents=(180.0, 220.0, 2.0)).export(tmp_path / "board.ply")
    with pytest.raises(InputError, match=r"board.ply: mesh: " + flat):
        _run_ingest(
            dict(ROW, modality="mesh"),
            {"mesh": str(tmp_path / "board.ply")},
            {"width": 160, "height": 120},
        )


def test_one_pixel_and_all_invalid_scans(tmp_path):
    write_abs(tmp_path / "one.abs", np.ones((1, 1, 3)))
    write_color(tmp_path / "one.png", np.zeros((1, 1, 3), np.uint8))
    write_pts(tmp_path / "p.pts", np.zeros((68, 2)))
    with pytest.raises(InputError, match=r"one.abs: xyz: the image is 1x1 px .* at least 16x16"):
        read_range_take(tmp_path / "one.abs", tmp_path / "one.png", tmp_path / "p.pts")
    write_abs(tmp_path / "none.abs", np.full((20, 20, 3), np.nan))
    write_color(tmp_path / "none.png", np.zeros((20, 20, 3), np.uint8))
    with pytest.raises(InputError, match="none.abs: xyz: no valid pixel"):
        read_range_take(tmp_path / "none.abs", tmp_path / "none.png", tmp_path / "p.pts")


def test_abs_header_promising_a_huge_image_is_refused_before_reading(tmp_path):
    path = tmp_path / "huge.abs"
    path.write_text("200000 rows\n300000 columns\npixels (flag X Y Z):\n1 0\n1 2\n3 4\n5 6\n")
    with pytest.raises(InputError, match=r"header: 200000 rows x 300000 columns = 6e\+10 pixels"):
        read_abs(path)


@pytest.mark.parametrize("placeholder", [0.0, -999999.0])
def test_a_placeholder_for_no_data_is_refused(tmp_path, take, placeholder):
    """0 or FRGC's -999999 written where NaN was meant (in an ``.npz``, or at pixels an
    ``.abs`` flags valid) is one line naming the file, the key and the point, not a scan of every
    pixel (whose fit then spanned the scene)."""
    xyz = take["xyz"].copy()
    hole = ~np.isfinite(xyz).all(axis=-1)
    share = f"{hole.mean():.0%}"
    xyz[hole] = placeholder
    np.savez(tmp_path / "p.npz", xyz=xyz)
    point = rf"\({placeholder:g}, {placeholder:g}, {placeholder:g}\)"
    with pytest.raises(InputError, match=rf"key 'xyz': {share} of the pixels are exactly {point}"):
        read_range(tmp_path / "p.npz")
    with pytest.raises(InputError, match="use NaN for no data") as exc:
        _ingest(_write(tmp_path, take) | {"xyz": tmp_path / "p.npz"})
    _one_line(exc, tmp_path / "p.npz")
    write_abs(tmp_path / "p.abs", xyz)  # every pixel flagged valid
    with pytest.raises(InputError, match=rf"X/Y/Z: {share} of the pixels flagged valid are"):
        read_range(tmp_path / "p.abs")


def test_gzip_range_text_reads_whatever_its_name(tmp_path, take):
    """An upper-case ``.ABS.GZ`` and a compressed file named ``.abs`` read as their gzip data
    (they failed with an 'ascii' codec error)."""
    write_abs(tmp_path / "t.abs.gz", take["xyz"])
    expected = read_range(tmp_path / "t.abs.gz")
    for name in ("T.ABS.GZ", "g.abs"):
        (tmp_path / name).write_bytes((tmp_path / "t.abs.gz").read_bytes())
        np.testing.assert_array_equal(read_range(tmp_path / name), expected)


# --- colour images -------------------------------------------------------------------------------


def test_grey_rgba_and_16_bit_colour_images_are_converted(tmp_path):
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    grey = rgb[:, :, 0]
    cv2.imwrite(str(tmp_path / "grey.png"), grey)
    np.testing.assert_array_equal(
        read_color(tmp_path / "grey.png"), np.repeat(grey[..., None], 3, 2)
    )
    bgra = np.dstack([rgb[:, :, ::-1], np.full((20, 30), 128, np.uint8)])
    cv2.imwrite(str(tmp_path / "rgba.png"), bgra)
    np.testing.assert_array_equal(read_color(tmp_path / "rgba.png"), rgb)
    cv2.imwrite(str(tmp_path / "deep.png"), rgb[:, :, ::-1].astype(np.uint16) * 257)
    np.testing.assert_array_equal(read_color(tmp_path / "deep.png"), rgb)
    cv2.imwrite(str(tmp_path / "deep_grey.png"), grey.astype(np.uint16) * 256)
    out = read_color(tmp_path / "deep_grey.png")
    assert out.shape == (20, 30, 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(out[:, :, 1], np.round(grey * 256.0 / 257).astype(np.uint8))


# --- ids -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "column, value", [("subject", "../x"), ("subject", "a/b"), ("take", "my take")]
)
def test_unsafe_ids_are_refused_naming_the_row(tmp_path, column, value):
    row = dict(subject="alice", take="n", kind="neutral", label="neutral", modality="range")
    row[column] = value
    cells = [
        row["subject"],
        row["take"],
        "neutral",
        "neutral",
        "range",
        "a.abs",
        "a.png",
        "",
        "",
        "",
        "a.pts",
    ]
    sheet = tmp_path / "s.tsv"
    sheet.write_text(
        HEADER + "alice\tm\tviseme\tcar\trange\ta\tb\t\t\t\tc\n" + "\t".join(cells) + "\n"
    )
    with pytest.raises(InputError, match=f"row 3, column '{column}': '{value}' is not an id"):
        read_sheet(sheet)


# --- a rotated scanner frame -----------------------------------------------------------------------


@pytest.mark.parametrize("degrees", [30.0, 60.0])
def test_a_rotated_scanner_frame_gives_the_same_fit(take, template, degrees):
    axis = np.array([0.3, -0.8, 0.52])
    R = Rotation.from_rotvec(np.radians(degrees) * axis / np.linalg.norm(axis)).as_matrix()
    t = np.array([120.0, -40.0, 300.0])
    config = repo_config()
    rules = fit_stage.Params.from_config(config).rules
    a = fit_take(template, take["landmarks"], take["xyz"], rules=rules, source="s1/a")
    b = fit_take(template, take["landmarks"], take["xyz"] @ R.T + t, rules=rules, source="s1/b")
    np.testing.assert_array_equal(a["valid"], b["valid"])
    ok = a["valid"]
    np.testing.assert_allclose(b["vertices"][ok], a["vertices"][ok] @ R.T + t, rtol=0, atol=1e-9)
    # the scanner is found where it is: the conventional frame as given, the rotated one moved
    assert scanner_view(take["xyz"]) is SCANNER_FRAME
    view = scanner_view(take["xyz"] @ R.T + t)
    np.testing.assert_allclose(view.centre, t, atol=1e-6)
    assert abs(view.axis @ R[:, 2]) > 1 - 1e-9
    np.testing.assert_allclose(np.abs(view.rotation @ R), np.eye(3), atol=1e-9)


def test_a_rotated_scanner_frame_gives_the_same_repair(take):
    from scan2morph.scan.repair import repair_range

    R = Rotation.from_rotvec([0.2, -0.5, 0.3]).as_matrix()
    t = np.array([100.0, 20.0, -300.0])
    a = repair_range(take["xyz"])[0]
    b = repair_range(take["xyz"] @ R.T + t)[0]
    np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b))
    np.testing.assert_allclose(b, a @ R.T + t, rtol=0, atol=1e-9)


def test_a_rotated_scanner_frame_passes_ingest(tmp_path, take):
    R = Rotation.from_euler("xyz", [30.0, -20.0, 45.0], degrees=True).as_matrix()
    part = _ingest(_write(tmp_path, take, xyz=take["xyz"] @ R.T + [10.0, 500.0, -80.0]))
    assert part is not None


# --- a full disk -----------------------------------------------------------------------------------


def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_is_one_line_naming_the_file(tmp_path, monkeypatch):
    import scan2morph.io.range_image as range_image

    xyz = np.ones((4, 5, 3))
    monkeypatch.setattr(Path, "write_text", _no_space)
    with pytest.raises(OutputError) as exc:
        write_pts(tmp_path / "a.pts", np.zeros((68, 2)))
    assert str(exc.value) == f"no space left on device writing {tmp_path / 'a.pts'}"
    monkeypatch.setattr(np, "savez_compressed", _no_space)
    with pytest.raises(OutputError, match="no space left on device writing .*a.npz$"):
        write_npz_range(tmp_path / "a.npz", xyz)
    monkeypatch.setattr(range_image, "_open_text", _no_space)
    with pytest.raises(OutputError, match="no space left on device writing .*a.abs.gz$"):
        write_abs(tmp_path / "a.abs.gz", xyz)
    # other OS errors stay what they are
    monkeypatch.setattr(range_image, "_open_text", lambda *a: open(tmp_path / "nowhere" / "x", "w"))
    with pytest.raises(FileNotFoundError):
        write_abs(tmp_path / "b.abs", xyz)


def test_a_full_disk_in_a_job_logs_one_line(tmp_path):
    code = (
        "import errno, numpy as np\n"
        "from pathlib import Path\n"
        "from scan2morph.jobs import run_job\n"
        "from scan2morph.io import write_pts\n"
        "def full(*a, **k):\n"
        "    raise OSError(errno.ENOSPC, 'No space left on device')\n"
        "Path.write_text = full\n"
        f"run_job(None, lambda: write_pts({str(tmp_path / 'a.pts')!r}, np.zeros((68, 2))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 1
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].endswith(
        f"no space left on device writing {tmp_path / 'a.pts'}"
    )


# --- errors that stop the whole run -------------------------------------------------------------------


def test_config_validation_fills_defaults_as_snakemake_does():
    from snakemake.utils import validate

    schema = ROOT / "schemas" / "config.schema.yaml"
    config = repo_config()
    for cfg in (config, {}):
        ours, theirs = copy.deepcopy(cfg), copy.deepcopy(cfg)
        validate_config(ours, schema)
        validate(theirs, str(schema))
        assert ours == theirs


@pytest.mark.parametrize(
    "extra, match",
    [
        ({"bogus_key": 1}, r"^config: bogus_key: unknown key \(known: align, "),
        ({"synthetic": {"scanner": {"foo": 2}}}, r"^config: synthetic\.scanner\.foo: unknown key"),
        (
            {"template": {"max_slope_deg": 95}},
            r"^config: template\.max_slope_deg: expected a value < 90, got 95$",
        ),
        ({"refine": {"flow_level": 3}}, r"^config: refine\.flow_level: expected a value <= 2"),
        ({"refine": {"flow_level": 0.5}}, r"^config: refine\.flow_level: "),
        (
            {"refine": {"jaw": {"fade_rmse_ratio": 0}}},
            r"^config: refine\.jaw\.fade_rmse_ratio: expected a value > 0, got 0$",
        ),
        (
            {"template": {"rim_share": 1.5}},
            r"^config: template\.rim_share: expected a value <= 1, got 1\.5$",
        ),
        ({"template": {"rim_share": "half"}}, r"^config: template\.rim_share: expected number"),
        (
            {"refine": {"aperture_iterations": -1}},
            r"^config: refine\.aperture_iterations: expected a value >= 0, got -1$",
        ),
        ({"refine": {"aperture_iterations": 1.5}}, r"^config: refine\.aperture_iterations: "),
    ],
)
def test_config_errors_are_one_short_line(extra, match):
    config = repo_config()
    for key, value in extra.items():
        config[key] = value if not isinstance(config.get(key), dict) else {**config[key], **value}
    with pytest.raises(InputError, match=match) as exc:
        validate_config(config, ROOT / "schemas" / "config.schema.yaml")
    assert "\n" not in str(exc.value) and len(str(exc.value)) < 400


@pytest.mark.parametrize(
    "section, old, new",
    [
        ("refine", {"jaw_prior": False}, "refine.jaw_prior: renamed to refine.jaw.prior"),
        ("refine", {"jaw_end": 0.4}, "refine.jaw_end: renamed to refine.jaw.end"),
        ("refine", {"lip_stretch": 0.2}, "refine.lip_stretch: renamed to refine.lip.stretch"),
        (
            "refine",
            {"lower_lip_shrink": 0.3},
            "refine.lower_lip_shrink: renamed to refine.lower_lip.shrink",
        ),
        ("align", {"kernel_k_mm": 0.5}, "align.kernel_k_mm: renamed to align.icp.kernel_k_mm"),
        ("align", {"max_rmse_mm": None}, "align.max_rmse_mm: renamed to align.icp.max_rmse_mm"),
    ],
)
def test_a_config_key_that_moved_is_named_with_its_new_place(section, old, new):
    """A user's config over the repo's (as Snakemake merges them) that still uses an old flat
    key: one line naming the new key, before any other check."""
    config = repo_config()
    config[section] |= old
    with pytest.raises(InputError, match=f"^config: {re.escape(new)}$"):
        validate_config(config, ROOT / "schemas" / "config.schema.yaml")
    # two old keys: still one line, naming both
    config["refine"] |= {"lip_prior": True}
    with pytest.raises(InputError, match="renamed to refine.lip.prior") as exc:
        validate_config(config, ROOT / "schemas" / "config.schema.yaml")
    assert "\n" not in str(exc.value) and new in str(exc.value)


def test_an_empty_cell_fails_only_its_subject(tmp_path):
    sheet = tmp_path / "s.tsv"
    sheet.write_text(HEADER + "bob\tn\tneutral\t\trange\ta.abs\ta.png\t\t\t\t\n")
    problems = subject_problems(read_sheet(sheet), schema=ROOT / "schemas" / "sheet.schema.yaml")
    assert problems["bob"][:1] == [f"{sheet} row 2 (bob/n): column 'label': empty"]
    # an empty landmarks cell is no problem: that take's landmarks are detected
    assert not [p for p in problems["bob"] if "'landmarks'" in p]


@pytest.mark.parametrize(
    "jaw, match",
    [
        (
            {"fade_rmse_ratio": 1.0},
            r"^config: refine\.jaw: fade_rmse_ratio: expected at least max_rmse_ratio \(1\.5\), "
            r"got 1\.0$",
        ),
        (
            {"start": 0.5},
            r"^config: refine\.jaw: start, end: expected 0 <= start < end <= 1, got 0\.5 and 0\.3$",
        ),
    ],
)
def test_settings_that_contradict_each_other_are_one_config_line(jaw, match):
    """What the schema cannot check, one setting against another, is found before any job: the
    take stages' parameters built from the config (the repo's passes)."""
    config = repo_config()
    validate_config(config, ROOT / "schemas" / "config.schema.yaml")
    check_stage_params(config)
    config["refine"]["jaw"] |= jaw
    validate_config(config, ROOT / "schemas" / "config.schema.yaml")  # each value is valid alone
    with pytest.raises(InputError, match=match):
        check_stage_params(config)


def test_a_subject_stages_contradicting_settings_stop_the_run_at_load():
    """The subject stages' parameters are built at load too: a membrane's mimic mass on the
    paper's steel shell stopped every subject in its own job; it is now one config line."""
    config = repo_config()
    config["modal"] = config["modal"] | {"preset": "paper", "mimic_mass_factor": 2.0}
    validate_config(config, ROOT / "schemas" / "config.schema.yaml")  # each value is valid alone
    with pytest.raises(InputError, match=r"^config modal: mimic_mass_factor: 2\.0 .* set it to 1"):
        check_stage_params(config)


@pytest.mark.slow  # starts Snakemake: not in make test-fast
@pytest.mark.parametrize(
    "text, line",
    [
        ("bogus_key: 1\n", "Error: config: bogus_key: unknown key"),
        (  # each value valid alone, the two together not: found before any job too
            "refine:\n  jaw:\n    fade_rmse_ratio: 1.0\n",
            "Error: config: refine.jaw: fade_rmse_ratio: expected at least max_rmse_ratio",
        ),
        (  # Snakemake keeps the last silently: refused as tools/check_config.py refuses it
            "modal:\n  modes: 10\nmodal:\n  preset: paper\n",
            "Error: {path}: line 3: key 'modal' given twice (first on line 1): keep one value",
        ),
    ],
)
def test_a_bad_config_stops_snakemake_in_a_few_lines(tmp_path, text, line):
    """``snakemake --configfile`` directly, without make run's tools/check_config.py first."""
    (tmp_path / "bad.yaml").write_text(text)
    status, lines = snakemake_dry_run(tmp_path, "bad.yaml")
    assert status != 0
    assert len(lines) <= 3
    assert lines[-1].startswith(line.format(path=tmp_path / "bad.yaml")), lines[-1]


# --- RGB-D and mesh takes (issue #18) ---
TINY_RGBD = dict(
    width=160, height=120, focal_px=250.0, color_width=160, color_height=120, color_focal_px=258.0
)


@pytest.fixture(scope="module")
def rgbd_files(tmp_path_factory):
    from scan2morph.synth.rgbd import make_rgbd_take, write_rgbd_take

    d = tmp_path_factory.mktemp("rgbd")
    res = make_rgbd_take("s1", "neutral", "neutral", "neutral", seed=3, params=dict(TINY_RGBD))
    files = {
        k: d / f for k, f in (("depth", "d.png"), ("color", "c.png"), ("intrinsics", "i.yaml"))
    }
    files["landmarks"] = d / "l.pts"
    write_rgbd_take(res, *files.values(), d / "truth.npz")
    return files


def _rgbd(files, **changed):
    return _run_ingest(
        dict(ROW, modality="rgbd"), {k: str(v) for k, v in (files | changed).items()}
    )


def _edit_yaml(src, dst, edit):
    doc = yaml.safe_load(Path(src).read_text())
    edit(doc)
    Path(dst).write_text(yaml.safe_dump(doc))
    return dst


def test_rgbd_take_reads_and_records_its_camera(rgbd_files):
    from scan2morph.store import paths

    part = _rgbd(rgbd_files)
    assert part.datasets[paths.raw("neutral", "xyz")].shape == (120, 160, 3)
    assert part.datasets[paths.camera("neutral", "modality")] == "rgbd"
    assert part.datasets[paths.camera("neutral", "K")][0, 0] == 258.0
    assert part.datasets[paths.camera("neutral", "pose")][0, 3] == -15.0  # the baseline, mm


@pytest.mark.parametrize(
    "factor, expected",
    [(0.001, "x 1000"), (1000.0, "x 0.001"), (0.1, "x 10"), (10.0, "x 0.1")],
)
def test_rgbd_depth_scale_off_by_1000_is_named(rgbd_files, tmp_path, factor, expected):
    """Off by 10 too: the face then lands beside the clicked points on the colour grid, and one
    outer eye corner on the background (whose distance to the other could look face-sized); the
    message is the scale's alone, without the landmark check's text."""

    def edit(doc):
        doc["depth_scale_mm"] *= factor

    bad = _edit_yaml(rgbd_files["intrinsics"], tmp_path / "i.yaml", edit)
    with pytest.raises(InputError, match=f"depth_scale_mm: .*{expected}.*plausible") as exc:
        _rgbd(rgbd_files, intrinsics=bad)
    assert exc.value.source == str(bad)
    assert "iBUG" not in exc.value.problem.replace("(iBUG 37, 46)", "")


def test_rgbd_depth_scale_off_by_10_without_landmarks_is_named(rgbd_files, tmp_path):
    """Without a landmark file nothing checked an RGB-D take's depth scale: off by 10, the
    repair (its thresholds in mm) cut the face apart and the detector refused it as a "profile
    view" with a 658 mm nose (audit7). A nearest object outside the depths a face is detected
    at, that the scale x 0.1, 10, 0.001 or 1000 puts there, names the scale, by the subject's
    check and the ingest; the right scale reads."""
    from scan2morph.io.check import take_file_problems

    files = {k: v for k, v in rgbd_files.items() if k != "landmarks"}
    _rgbd(files)  # the right scale, no landmarks
    for factor, expected in ((10.0, "x 0.1"), (0.1, "x 10"), (1e-3, "x 1000")):

        def edit(doc, factor=factor):
            doc["depth_scale_mm"] *= factor

        bad = _edit_yaml(files["intrinsics"], tmp_path / "bad.yaml", edit)
        match = rf"bad.yaml: depth_scale_mm: .* \({expected}\) it is \d+ mm away"
        with pytest.raises(InputError, match=match):
            _rgbd(files, intrinsics=bad)
        (problem,) = take_file_problems("rgbd", files | {"intrinsics": bad})
        assert re.search(match, problem), problem


@pytest.mark.parametrize(
    "edit, match",
    [
        (
            lambda d: d.update(width=320),
            r"i.yaml: width/height: 320x120 but the depth image d.png is 160x120",
        ),
        (
            lambda d: d["color"].update(height=240),
            r"color.width/color.height: 160x240 but the color",
        ),
        (lambda d: d.pop("fx"), r"i.yaml: fx: missing"),
        (
            lambda d: d["color"].update(R=[[1, 0, 0], [0, 1, 0], [0, 0, 2]]),
            "color.R: not a rotation",
        ),
        (lambda d: d.update(depth_scale_mm=0), "depth_scale_mm: expected > 0"),
        (
            lambda d: d["color"].update(T=[-0.015, 0.0, 0.0]),
            r"color.T: \|T\| = 0.015 is below 1 mm; T must be in mm \(is it in metres\?\)",
        ),
        (  # the bad-input audit's F1b: read as a zero baseline, the colour was 19 mm RMS off
            lambda d: d["color"].pop("T"),
            r"i.yaml: color.T: missing \(the depth -> colour translation, mm",
        ),
        (
            lambda d: d.update(fx=d["fx"] / 160, fy=d["fy"] / 120, cx=0.5, cy=0.5),
            r"i.yaml: fx: 1.5625 px for a width of 160 px is a \d+° field of view .* normalised",
        ),
        (
            lambda d: d["color"].update(cx=0, cy=0),
            r"color.cx/color.cy: the principal point \(0, 0\) px lies at the image's corner, not near "
            r"the centre of the 160x120 image \(79.5, 59.5\)",
        ),
    ],
)
def test_rgbd_intrinsics_that_do_not_fit(rgbd_files, tmp_path, edit, match):
    bad = _edit_yaml(rgbd_files["intrinsics"], tmp_path / "i.yaml", edit)
    with pytest.raises(InputError, match=match) as exc:
        _rgbd(rgbd_files, intrinsics=bad)
    assert exc.value.source == str(bad)


def test_rgbd_intrinsics_with_a_key_given_twice(rgbd_files, tmp_path):
    """A pasted second value is refused naming the key (PyYAML kept the last silently), and a
    colour camera at the depth camera (T = 0) stays valid."""
    bad = tmp_path / "i.yaml"
    bad.write_text(rgbd_files["intrinsics"].read_text() + "fx: 300.0\n")
    with pytest.raises(InputError, match=r"line \d+: key 'fx' given twice \(first on line \d+\)"):
        _rgbd(rgbd_files, intrinsics=bad)
    same = _edit_yaml(
        rgbd_files["intrinsics"], tmp_path / "t0.yaml", lambda d: d["color"].update(T=[0, 0, 0])
    )
    assert read_rgbd_intrinsics(same).T.tolist() == [0.0, 0.0, 0.0]
    # a YAML merge key ("<<: *anchor") is no key given twice
    from scan2morph.io.yaml_text import load_yaml

    text = "a: &a {fx: 500, fy: 510}\nb:\n  <<: *a\n  fy: 520\n"
    assert load_yaml(text) == {"a": {"fx": 500, "fy": 510}, "b": {"fx": 500, "fy": 520}}


def test_stereo_calibration_with_a_key_given_twice(tmp_path, stereo):
    """OpenCV kept the first of two ``T`` keys silently."""
    write_stereo_calibration(tmp_path / "c.yaml", stereo["calib"])
    text = (tmp_path / "c.yaml").read_text()
    t_block = text[text.index("T: !!opencv-matrix") :]
    (tmp_path / "c.yaml").write_text(text + t_block.replace("T:", "T:", 1))
    with pytest.raises(InputError, match=r"c.yaml: T: given twice; keep one value"):
        read_stereo_calibration(tmp_path / "c.yaml")


def test_rgbd_unreadable_or_wrong_depth_files(rgbd_files, tmp_path):
    (tmp_path / "junk.png").write_bytes(b"not a png at all")
    with pytest.raises(InputError, match="depth: cannot decode the PNG"):
        _rgbd(rgbd_files, depth=tmp_path / "junk.png")
    write_color(tmp_path / "rgb.png", np.zeros((120, 160, 3), np.uint8))
    with pytest.raises(InputError, match="expected a 16-bit single-channel PNG, got uint8 with 3"):
        _rgbd(rgbd_files, depth=tmp_path / "rgb.png")
    np.savez(tmp_path / "d.npz", z=np.ones((120, 160)))
    with pytest.raises(InputError, match=r"key 'depth' missing \(found \['z'\]\)"):
        _rgbd(rgbd_files, depth=tmp_path / "d.npz")
    (tmp_path / "i.yaml").write_text("width: [1, 2\n")
    with pytest.raises(InputError, match="cannot read as YAML"):
        _rgbd(rgbd_files, intrinsics=tmp_path / "i.yaml")


@pytest.fixture(scope="module")
def mesh_files(tmp_path_factory):
    from scan2morph.synth.mesh_scan import make_mesh_take, write_mesh_take

    d = tmp_path_factory.mktemp("mesh")
    res = make_mesh_take("s1", "neutral", "neutral", "neutral", seed=3)
    write_mesh_take(res, d / "m.ply", d / "m.txt", d / "truth.npz")
    return {"mesh": d / "m.ply", "landmarks": d / "m.txt", "scan": res}


@pytest.fixture(scope="module")
def small_scan():
    """A head-sized mesh of 162 vertices (an icosphere 180 mm across), for the mesh file's own
    refusals (its format, material, texture and face lines), which the reader gives before it
    looks at the shape or the number of vertices: the same messages as on the 54k-vertex face
    scan, at a fraction of its write and read time."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=90.0)
    return {"vertices": np.asarray(sphere.vertices), "faces": np.asarray(sphere.faces)}


def _mesh(files, **changed):
    files = {k: str(v) for k, v in (files | changed).items() if k != "scan"}
    return _run_ingest(dict(ROW, modality="mesh"), files, {"width": 160, "height": 120})


def test_mesh_take_reads_and_records_its_camera(mesh_files):
    from scan2morph.store import paths

    part = _mesh(mesh_files)
    assert part.datasets[paths.camera("neutral", "modality")] == "mesh"
    assert part.datasets[paths.camera("neutral", "size")].tolist() == [160, 120]


def test_mesh_without_faces(mesh_files, tmp_path):
    import trimesh

    cloud = trimesh.PointCloud(mesh_files["scan"]["vertices"])
    cloud.export(tmp_path / "cloud.ply")
    with pytest.raises(InputError, match=r"mesh: no faces \(\d+ vertices: a point cloud\?\)"):
        _mesh(mesh_files, mesh=tmp_path / "cloud.ply")


def test_mesh_texture_missing_names_the_file(mesh_files, small_scan, tmp_path):
    import trimesh
    from PIL import Image

    scan = small_scan
    uv = np.zeros((len(scan["vertices"]), 2))
    visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.new("RGB", (8, 8)))
    trimesh.Trimesh(scan["vertices"], scan["faces"], visual=visual, process=False).export(
        tmp_path / "face.obj"
    )
    for png in tmp_path.glob("*.png"):
        png.unlink()
    with pytest.raises(InputError, match=r"texture: .*names 'material_0.png', which is missing"):
        _mesh(mesh_files, mesh=tmp_path / "face.obj")


def test_mesh_landmarks_off_the_mesh_or_in_metres(mesh_files, tmp_path):
    from scan2morph.synth.mesh_scan import write_landmarks3d

    lm = mesh_files["scan"]["landmarks"]
    write_landmarks3d(tmp_path / "off.txt", lm + [0.0, 0.0, 30.0])
    with pytest.raises(
        InputError, match=r"landmarks: point \d+ lies [23]\d.* mm from the mesh m.ply"
    ):
        _mesh(mesh_files, landmarks=tmp_path / "off.txt")
    # in metres on a mesh in mm: the landmark file is named, not the mesh (whose unit is right)
    write_landmarks3d(tmp_path / "lm_m.txt", lm / 1000.0)
    with pytest.raises(
        InputError,
        match=r"lm_m.txt: face size: the outer eye corners \(iBUG 37, 46\) are 0.0\d+ units "
        r"apart, expected 50-150 mm, on the mesh m.ply, which is \d+(\.\d+)? mm across \(the "
        r"landmarks look like metres: give them in the mesh's frame and unit\)",
    ):
        _mesh(mesh_files, landmarks=tmp_path / "lm_m.txt")
    # the subject's check job finds it too, before any take job (audit finding 11)
    from scan2morph.io.check import take_file_problems

    files = {"mesh": mesh_files["mesh"], "landmarks": tmp_path / "lm_m.txt"}
    (problem,) = take_file_problems("mesh", files)
    assert problem.startswith(f"{tmp_path / 'lm_m.txt'}: face size: the outer eye corners")
    assert problem.endswith(
        "(the landmarks look like metres: give them in the mesh's frame and unit)"
    )
    assert take_file_problems("mesh", files | {"landmarks": mesh_files["landmarks"]}) == []
    (tmp_path / "short.txt").write_text("# 67 points\n" + "1 2 3\n" * 67)
    with pytest.raises(
        InputError, match=r"got 67 points \(lines 'x y z'\); accepted: 68 \(iBUG-68\) or 51"
    ):
        _mesh(mesh_files, landmarks=tmp_path / "short.txt")


def test_mesh_without_landmarks_in_cm_is_refused_before_its_surface_is_searched(
    mesh_files, tmp_path
):
    """Without landmarks only the mesh's own size tells its unit: a head in cm is refused by the
    subject's check and by the ingest, naming its size and the unit (before the nose-tip search,
    whose 35 mm neighbourhoods would hold the whole 10x smaller mesh: a real head in its own unit
    took 17 GB there), and reads once the sheet gives the unit."""
    import trimesh

    from scan2morph.io.check import take_file_problems

    scan = mesh_files["scan"]
    mesh = trimesh.Trimesh(scan["vertices"] / 10.0, scan["faces"], process=False)
    mesh.export(tmp_path / "cm.ply")
    files = {"mesh": tmp_path / "cm.ply"}
    match = (
        r"cm.ply: mesh size: \d+(\.\d+)? x .* mm across as read, expected a face or head "
        r"60-1000 mm across at its largest \(it looks like cm: give its unit in the sheet's "
        r"units column"
    )
    (problem,) = take_file_problems("mesh", files)
    assert re.search(match, problem), problem
    assert take_file_problems("mesh", files, 10.0) == []
    with pytest.raises(InputError, match=match):
        _run_ingest(
            dict(ROW, modality="mesh"), {"mesh": str(files["mesh"])}, {"width": 160, "height": 120}
        )
    part = _run_ingest(
        dict(ROW, modality="mesh", units="cm"),
        {"mesh": str(files["mesh"])},
        {"width": 160, "height": 120},
    )
    from scan2morph.store import paths

    assert part.datasets[paths.camera("neutral", "size")].tolist() == [160, 120]
    tiny = trimesh.Trimesh(scan["vertices"] / 1000.0, scan["faces"], process=False)
    tiny.export(tmp_path / "tiny.ply")
    (problem,) = take_file_problems("mesh", {"mesh": tmp_path / "tiny.ply"})
    assert "it looks like metres: give its unit in the sheet's units column" in problem


def test_the_unit_named_is_the_one_that_gives_a_head_its_usual_size():
    """Of the units that put a size within the band, the one nearest the band's middle: a head
    8.55 units across (the real head's GLB) is 217 mm in inches against 86 mm in cm; one 38
    units across is 382 mm in cm (965 mm in inches); an eye span of 0.09 is metres."""
    from scan2morph.io.mesh_scan import MESH_EXTENT_MM
    from scan2morph.io.take import likely_unit

    assert likely_unit(8.553, MESH_EXTENT_MM) == "inches"
    assert likely_unit(38.17, MESH_EXTENT_MM) == "cm"
    assert likely_unit(0.38, MESH_EXTENT_MM) == "metres"
    assert likely_unit(0.09, (50.0, 150.0)) == "metres"
    assert likely_unit(1e9, MESH_EXTENT_MM) is None


def test_a_face_too_small_for_its_nose_names_the_mesh_size(mesh_files):
    """A mesh whose nose has no face profile 8-20 mm around it (the real head given in cm, 85 mm
    across, as the old unit guess had it, met this after its nose search): the refusal says how
    big the mesh is as read and where its unit goes. The scan's own view, its head and nose
    scaled down 20 times: 19 mm across, no profile that far from the tip."""
    import dataclasses

    import trimesh

    from scan2morph.io.mesh_view import face_up, face_view

    scan = mesh_files["scan"]
    view = face_view(trimesh.Trimesh(scan["vertices"], scan["faces"], process=False))
    with pytest.raises(
        InputError,
        match=r"small.ply: mesh: no surface 8-20 mm from the nose tip along the face's profile "
        r"\(expected a face around the nose; the mesh is 19.0\d mm across: if that is not its "
        r"true size, give its unit in the sheet's units column\)",
    ):
        face_up(
            scan["vertices"] / 20.0, dataclasses.replace(view, tip=view.tip / 20.0), "small.ply"
        )


def test_mesh_landmarks_mirrored(mesh_files, tmp_path):
    from scan2morph.synth.mesh_scan import write_landmarks3d

    lm = mesh_files["scan"]["landmarks"].copy()
    lm[[36, 45]] = lm[[45, 36]]  # the outer eye corners exchanged
    write_landmarks3d(tmp_path / "mirrored.txt", lm)
    with pytest.raises(InputError, match="landmarks: mirrored left/right"):
        _mesh(mesh_files, landmarks=tmp_path / "mirrored.txt")


def test_mesh_unreadable_file(mesh_files, tmp_path):
    (tmp_path / "junk.glb").write_bytes(b"\x00garbage" * 10)
    with pytest.raises(InputError, match="mesh: cannot read"):
        _mesh(mesh_files, mesh=tmp_path / "junk.glb")
    with pytest.raises(InputError, match="file not found"):
        _mesh(mesh_files, mesh=tmp_path / "absent.obj")


def _textured_obj(scan, folder, uv=True):
    """The scan as an OBJ (+ MTL + 8 x 8 texture) in ``folder``, with zero UVs or none."""
    import trimesh
    from PIL import Image

    if uv:
        coords = np.zeros((len(scan["vertices"]), 2))
        visual = trimesh.visual.TextureVisuals(uv=coords, image=Image.new("RGB", (8, 8)))
    else:
        visual = None
    mesh = trimesh.Trimesh(scan["vertices"], scan["faces"], visual=visual, process=False)
    mesh.export(folder / "face.obj")
    return folder / "face.obj"


def test_obj_whose_mtl_is_missing_is_refused_unless_the_sheet_gives_the_texture(
    small_scan, tmp_path
):
    """trimesh puts a grey 2 x 2 placeholder in place of a missing MTL: the take rendered flat
    grey and was recorded as textured. Refused naming the MTL; the sheet's texture reads it;
    without UVs it is a geometry-only mesh."""
    from scan2morph.io.check import take_file_problems
    from scan2morph.io.mesh_scan import colour_source, read_mesh

    obj = _textured_obj(small_scan, tmp_path)
    (tmp_path / "material.mtl").unlink()
    match = (
        r"face.obj: mtllib 'material.mtl' is missing \(the mesh has UVs but no material\); put "
        r"the MTL and its texture beside the OBJ or give the texture in the sheet's texture column"
    )
    with pytest.raises(InputError, match=match):
        read_mesh(obj)
    (problem,) = take_file_problems("mesh", {"mesh": obj})
    assert re.search(match, problem), problem
    assert colour_source(read_mesh(obj, tmp_path / "material_0.png")) == "texture"
    # an MTL trimesh finds is the mesh's, named as exporters name it: an absolute path from
    # another machine (found by its name beside the OBJ), a subfolder; a second mtllib that
    # trimesh never reads is not asked for
    for case, head in {
        "absolute": "mtllib /elsewhere/on/another/disk/material.mtl",
        "subfolder": "mtllib export/material.mtl",
        "second": "mtllib material.mtl\nmtllib extra_not_here.mtl",
    }.items():
        folder = tmp_path / case
        (folder / "export").mkdir(parents=True)
        found = _textured_obj(small_scan, folder)
        if case == "subfolder":
            (folder / "material.mtl").rename(folder / "export" / "material.mtl")
        text = re.sub(r"(?m)^mtllib .*$", head, found.read_text(), count=1)
        found.write_text(text)
        assert colour_source(read_mesh(found)) == "texture", case
    # trimesh's stand-in in the other ways it falls back, each named: an OBJ with UVs and no
    # mtllib, an MTL without the faces' material
    bare = _textured_obj(small_scan, tmp_path / "absolute")
    bare.write_text(re.sub(r"(?m)^mtllib .*\n", "", bare.read_text()))
    with pytest.raises(InputError, match=r"the mesh has UVs but names no material \(no mtllib"):
        read_mesh(bare)
    other = _textured_obj(small_scan, tmp_path / "second")
    mtl = other.parent / "material.mtl"
    mtl.write_text(mtl.read_text().replace("newmtl material_0", "newmtl something_else"))
    with pytest.raises(InputError, match=r"usemtl 'material_0' is not in mtllib 'material.mtl'"):
        read_mesh(other)
    other.write_text(re.sub(r"(?m)^usemtl .*\n", "", other.read_text()))  # faces name none
    with pytest.raises(InputError, match=r"mtllib 'material.mtl' holds no material the faces"):
        read_mesh(other)
    (tmp_path / "plain").mkdir()
    plain = _textured_obj(small_scan, tmp_path / "plain", uv=False)
    plain.write_text("mtllib gone.mtl\nusemtl material_0\n" + plain.read_text())
    assert colour_source(read_mesh(plain)) == "shading"


def _split_material(obj, second: str):
    """Give the last half of an OBJ's faces the material ``second`` (a ``usemtl`` line)."""
    lines = obj.read_text().splitlines()
    faces = [k for k, line in enumerate(lines) if line.startswith("f ")]
    lines.insert(faces[len(faces) // 2], f"usemtl {second}")
    obj.write_text("\n".join(lines) + "\n")


def test_obj_materials_are_checked_against_their_mtl(small_scan, tmp_path):
    """trimesh packs an OBJ's materials into one image: a material the MTL lacks became a tile
    of its grey stand-in (those faces rendered flat grey, the mesh read as textured), and two
    colour-only materials (``Kd``) became an image of flat tiles (read as a texture). A name the
    MTL lacks is refused, naming the line, the material and the MTL's materials; colour-only
    materials, however many, are shading; several materials with images are a texture. The
    word ``mtllib`` in a comment above the mtllib line (trimesh takes the name after its
    first occurrence) does not lose the material."""
    from scan2morph.io.check import take_file_problems
    from scan2morph.io.mesh_scan import colour_source, read_mesh

    (tmp_path / "undefined").mkdir()
    obj = _textured_obj(small_scan, tmp_path / "undefined")
    _split_material(obj, "zz")
    line = obj.read_text().splitlines().index("usemtl zz") + 1
    match = rf"face.obj: line {line}: usemtl 'zz' is not in mtllib 'material.mtl' \(its materials: 'material_0'\)"
    with pytest.raises(InputError, match=match):
        read_mesh(obj)
    (problem,) = take_file_problems("mesh", {"mesh": obj})
    assert re.search(match, problem), problem
    mtl = obj.parent / "material.mtl"
    second = mtl.read_text().replace("newmtl material_0", "newmtl zz")
    mtl.write_text(mtl.read_text() + "\n" + second)
    assert colour_source(read_mesh(obj)) == "texture"  # both materials have the image
    colours = _colour_only_obj(small_scan, tmp_path / "colours", uv=True)
    _split_material(colours, "green")
    mtl = colours.parent / "material.mtl"
    mtl.write_text(mtl.read_text() + "newmtl green\nKd 0.2 0.8 0.2\n")
    assert colour_source(read_mesh(colours)) == "shading"
    (tmp_path / "comment").mkdir()
    commented = _textured_obj(small_scan, tmp_path / "comment")
    commented.write_text("# converted by mtllib-tool 2.1\n" + commented.read_text())
    assert colour_source(read_mesh(commented)) == "texture"


def _colour_only_obj(scan, folder, uv):
    """The scan as an OBJ in ``folder`` whose MTL gives a colour (``Kd``) and no image."""
    folder.mkdir()
    obj = _textured_obj(scan, folder, uv=uv)
    if not uv:
        obj.write_text("mtllib material.mtl\nusemtl material_0\n" + obj.read_text())
    (folder / "material.mtl").write_text("newmtl material_0\nKd 0.8 0.2 0.2\n")
    for png in folder.glob("*.png"):
        png.unlink()
    return obj


def test_obj_whose_material_has_a_colour_and_no_image_is_shaded(
    mesh_files, small_scan, tmp_path, caplog
):
    """An MTL with ``Kd`` and no ``map_Kd`` (a per-material colour) is no texture: the mesh
    reads as shaded with UVs or without, and the face scan's take is shaded, with the
    geometry-only warning."""
    from scan2morph.io.mesh_scan import colour_source, read_mesh

    for uv in (True, False):
        obj = _colour_only_obj(small_scan, tmp_path / f"uv{uv}", uv)
        assert colour_source(read_mesh(obj)) == "shading"
    obj = _colour_only_obj(mesh_files["scan"], tmp_path / "face", uv=False)
    with caplog.at_level("WARNING", logger="scan2morph"):
        part = _mesh(mesh_files, mesh=obj)
    assert "no texture and no vertex colours: rendered with shading" in caplog.text
    from scan2morph.store import paths

    assert part.datasets[paths.camera("neutral", "color_source")] == "shading"


def test_obj_cut_short_or_with_0_based_faces_names_the_line(mesh_files, small_scan, tmp_path):
    """A truncated OBJ (its last face line cut) lost its faces silently and was blamed on its
    landmarks; 0-based faces were shifted by one vertex and wrapped to the last one. Both are
    refused naming the face line, by the check and the ingest. Negative (relative) indices are
    valid OBJ: they read as the same faces."""
    import trimesh

    from scan2morph.io.check import take_file_problems
    from scan2morph.io.mesh_scan import read_mesh

    scan = small_scan
    trimesh.Trimesh(scan["vertices"], scan["faces"], process=False).export(tmp_path / "a.obj")
    text = (tmp_path / "a.obj").read_text()
    middle = (text.index("\nf ") + len(text)) // 2  # of the face lines
    cut = text.rindex("\nf ", 0, middle) + 4  # within a face line
    (tmp_path / "cut.obj").write_text(text[:cut])
    line = text[:cut].count("\n") + 1
    match = rf"cut.obj: face line {line}: 1 vertex, expected 3 or more: the file looks cut short"
    (problem,) = take_file_problems("mesh", {"mesh": tmp_path / "cut.obj"})
    assert re.search(match, problem), problem
    with pytest.raises(InputError, match=match):
        _mesh(mesh_files, mesh=tmp_path / "cut.obj")
    # cut, then ended by a newline (a tool that finishes what it wrote) and a blank line
    (tmp_path / "cut.obj").write_text(text[:cut] + "\n\n")
    with pytest.raises(InputError, match=match):
        read_mesh(tmp_path / "cut.obj")
    v, f = scan["vertices"], scan["faces"]
    vertices = "".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in v)
    (tmp_path / "zero.obj").write_text(vertices + "".join(f"f {a} {b} {c}\n" for a, b, c in f))
    with pytest.raises(
        InputError,
        match=rf"zero.obj: face line {len(v) + 1}: vertex index 0 \(OBJ indices start at 1",
    ):
        read_mesh(tmp_path / "zero.obj")
    back = f - len(v)  # -1 is the last vertex above the face
    (tmp_path / "rel.obj").write_text(vertices + "".join(f"f {a} {b} {c}\n" for a, b, c in back))
    relative = read_mesh(tmp_path / "rel.obj")
    np.testing.assert_array_equal(relative.vertices[relative.faces], v[f])
    (tmp_path / "far.obj").write_text("v 0 0 0\nv 1 0 0\nf -1 -2 -3\n")
    with pytest.raises(InputError, match=r"far.obj: face line 3: vertex index -3 counts back"):
        read_mesh(tmp_path / "far.obj")
    # a stray 2-vertex face line inside a file (trimesh drops it: the rest is the mesh)
    ones = "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)
    (tmp_path / "stray.obj").write_text(vertices + "f 1 2\n" + ones)
    np.testing.assert_array_equal(read_mesh(tmp_path / "stray.obj").faces, f)


def test_textured_obj_cut_inside_its_last_face_line_names_the_line(small_scan, tmp_path):
    """A textured OBJ cut inside a face line's last reference (``f 9/9 5/5 1``: three vertices,
    one without its texture coordinate) made trimesh drop every UV of the file: the renderer
    then crashed with a traceback and the take's job failed, stopping its subject (audit7).
    Refused naming the line, by the check and the reader, as is such a line inside a file."""
    from scan2morph.io.check import take_file_problems
    from scan2morph.io.mesh_scan import read_mesh

    obj = _textured_obj(small_scan, tmp_path)
    text = obj.read_text()
    last = text.rstrip("\n").rsplit("\n", 1)[1]  # f a/a b/b c/c
    cut = text.rstrip("\n")[: -len(last)] + last.rsplit("/", 1)[0].rsplit(" ", 1)[0] + " 1"
    obj.write_text(cut)
    line = cut.count("\n") + 1
    match = rf"face.obj: face line {line}: vertex references of different forms .*cut short"
    (problem,) = take_file_problems("mesh", {"mesh": obj})
    assert re.search(match, problem), problem
    with pytest.raises(InputError, match=match):
        read_mesh(obj)
    lines = text.split("\n")
    inner = next(i for i, t in enumerate(lines) if t.startswith("f ")) + 2
    lines[inner] = lines[inner].rsplit("/", 1)[0]  # f a/a b/b c
    obj.write_text("\n".join(lines))
    with pytest.raises(InputError, match=rf"face line {inner + 1}: vertex references"):
        read_mesh(obj)


def test_mesh_file_of_another_format_or_cut_short(mesh_files, tmp_path):
    """A PLY named .obj read as an OBJ without faces ('a point cloud?'); a binary PLY cut short
    gave trimesh's words."""
    import shutil

    from scan2morph.io.mesh_scan import read_mesh

    shutil.copy(mesh_files["mesh"], tmp_path / "face.obj")
    with pytest.raises(
        InputError,
        match=r"face.obj: mesh: the file is not OBJ text \(it starts with 'ply': a PLY file\); "
        r"name it .ply",
    ):
        read_mesh(tmp_path / "face.obj")
    data = mesh_files["mesh"].read_bytes()
    (tmp_path / "half.ply").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"half.ply: mesh: the file is shorter than its PLY"):
        read_mesh(tmp_path / "half.ply")


def test_check_refuses_a_mesh_without_triangles_of_area_as_the_ingest_does(mesh_files, tmp_path):
    """Every triangle collapsed, or a single triangle: the check passed them, the ingest
    refused them. Both now give the reader's one line."""
    import trimesh

    from scan2morph.io.check import take_file_problems

    v, f = mesh_files["scan"]["vertices"], mesh_files["scan"]["faces"].copy()
    f[:, 2] = f[:, 1]
    trimesh.Trimesh(v, f, process=False).export(tmp_path / "flat.ply")
    trimesh.Trimesh(v[:3], [[0, 1, 2]], process=False).export(tmp_path / "one.ply")
    for name, n in (("flat.ply", 0), ("one.ply", 1)):
        match = rf"{name}: mesh: {n} triangles of non-zero area \(expected a face\)"
        (problem,) = take_file_problems("mesh", {"mesh": tmp_path / name})
        assert re.search(match, problem), problem
        with pytest.raises(InputError, match=match):
            _mesh(mesh_files, mesh=tmp_path / name)


def test_a_unit_given_to_a_mesh_in_mm_says_the_unit_is_wrong(mesh_files):
    """``units: m`` on a mesh in mm said it 'looks like µm' (no unit the column takes): the
    message says what the unit makes of it and that the data are in mm already."""
    from scan2morph.io.check import take_file_problems

    match = (
        r"with the unit given \(1000 mm per unit\) it comes out [\d.e+]+ mm; without it, "
        r"\d+(\.\d+)? mm, a face's size: the data are in mm already and the value in the sheet's "
        r"units column is wrong \(leave it empty for mm\)"
    )
    (problem,) = take_file_problems("mesh", {"mesh": mesh_files["mesh"]}, 1000.0)
    assert re.search(r"m.ply: mesh size: .* mm across in the sheet's unit, .*" + match, problem)
    row = dict(ROW, modality="mesh", units="m")
    for files in (mesh_files, {"mesh": mesh_files["mesh"]}):
        files = {k: str(v) for k, v in files.items() if k != "scan"}
        with pytest.raises(InputError, match=r"m.ply: (face|mesh) size: .*" + match):
            _run_ingest(row, files, {"width": 160, "height": 120})


def test_rgbd_intrinsics_of_an_image_cropped_to_the_face_are_valid(rgbd_files, tmp_path):
    """A crop moves the principal point off-centre (here 5% from the side): still valid; an
    offset from the centre (3, -2) px is refused as (0, 0) is."""
    crop = _edit_yaml(
        rgbd_files["intrinsics"], tmp_path / "crop.yaml", lambda d: d["color"].update(cx=8.0)
    )
    assert read_rgbd_intrinsics(crop).color.K[0, 2] == 8.0
    offset = _edit_yaml(
        rgbd_files["intrinsics"], tmp_path / "off.yaml", lambda d: d["color"].update(cx=3, cy=-2)
    )
    with pytest.raises(InputError, match=r"color.cx/color.cy: the principal point \(3, -2\)"):
        read_rgbd_intrinsics(offset)
