"""Readers and writers: round trips and every bad-input message."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.io import (
    read_abs,
    read_color,
    read_npz_range,
    read_pts,
    read_range,
    read_range_take,
    write_abs,
    write_color,
    write_npz_range,
    write_pts,
)


@pytest.fixture
def xyz():
    rng = np.random.default_rng(0)
    h, w = 7, 9
    xyz = rng.normal(0.0, 100.0, (h, w, 3))
    xyz[rng.random((h, w)) < 0.2] = np.nan
    return xyz


@pytest.mark.parametrize("name", ["scan.abs", "scan.abs.gz"])
def test_abs_round_trip(tmp_path, xyz, name):
    path = tmp_path / name
    write_abs(path, xyz)
    back = read_abs(path)
    assert back.shape == xyz.shape
    np.testing.assert_array_equal(np.isnan(back), np.isnan(xyz))
    np.testing.assert_allclose(back[~np.isnan(xyz)], xyz[~np.isnan(xyz)], atol=5e-7)
    if name.endswith(".gz"):
        assert gzip.open(path, "rt").readline().strip() == "7 rows"
    first = path.read_bytes()
    write_abs(path, xyz)
    assert path.read_bytes() == first  # byte-reproducible (no gzip timestamp)


def test_abs_layout_is_frgc(tmp_path):
    """Flags, then X, Y and Z lines, row-major from the top row, -999999 for no data."""
    xyz = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3)
    xyz[0, 1] = np.nan
    path = tmp_path / "a.abs"
    write_abs(path, xyz)
    lines = path.read_text().splitlines()
    assert lines[:3] == ["2 rows", "3 columns", "pixels (flag X Y Z):"]
    assert lines[3].split() == ["1", "0", "1", "1", "1", "1"]
    assert float(lines[4].split()[1]) == -999999.0
    assert [float(v) for v in lines[4].split()][3] == 9.0  # X of row 1, column 0


def _abs_text(rows=2, cols=2, lines=None):
    body = lines or ["1 1 1 1", "1 2 3 4", "5 6 7 8", "9 10 11 12"]
    return f"{rows} rows\n{cols} columns\npixels (flag X Y Z):\n" + "\n".join(body) + "\n"


@pytest.mark.parametrize(
    "text, match",
    [
        (_abs_text(lines=["1 1 1 1", "1 2 3 4"]), "truncated.*missing Y, Z"),
        (
            _abs_text(lines=["1 1 1 1", "1 2 3 4", "5 6 7 8", "9 10"]),
            "line .Z.: .* got 2 \\(truncated file\\?\\)",
        ),
        (
            _abs_text(lines=["1 1 1 1", "1 2 3", "5 6 7 8", "9 10 11 12"]),
            "line 'X': expected 2\\*2 = 4 values, got 3",
        ),
        (
            _abs_text(lines=["1 1 1 1", "1 2 3 4", "5 6 x 8", "9 10 11 12"]),
            "line 'Y': non-numeric value 'x'",
        ),
        (_abs_text(lines=["1 1 2 1", "1 2 3 4", "5 6 7 8", "9 10 11 12"]), "only 0 or 1"),
        ("2 rows\n", "truncated header"),
        ("2 rows\nwide\npixels (flag X Y Z):\n", "header line 2: expected '<C> columns'"),
        ("", "truncated header"),
    ],
)
def test_abs_bad_input(tmp_path, text, match):
    path = tmp_path / "bad.abs"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        read_abs(path)
    assert str(path) in str(info.value)


def test_abs_that_is_not_ascii_says_why(tmp_path):
    """Before: "cannot read as FRGC .abs text: 'ascii' codec can't decode byte 0xef in position
    0: ordinal not in range(128)" for a file an editor saved with a byte-order mark (audit
    finding 15)."""
    path = tmp_path / "bom.abs"
    path.write_bytes(b"\xef\xbb\xbf" + _abs_text().encode())
    with pytest.raises(InputError) as info:
        read_abs(path)
    assert str(info.value) == (
        f"{path}: the file starts with a byte-order mark (BOM, as an editor saves UTF-8 text); "
        "expected FRGC .abs text in plain ASCII: save it without BOM"
    )
    path.write_bytes(
        _abs_text(lines=["1 1 1 1", "1 2 3 4", "5 6 7 8", "9 10 11 1\xb5"]).encode("latin-1")
    )
    with pytest.raises(InputError) as info:
        read_abs(path)
    assert str(info.value) == (
        f"{path}: byte 0xb5 is not ASCII text; expected FRGC .abs text (ASCII numbers)"
    )


def test_abs_truncated_gzip(tmp_path, xyz):
    path = tmp_path / "scan.abs.gz"
    write_abs(path, xyz)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="scan.abs.gz"):
        read_abs(path)


def test_abs_missing_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_abs(tmp_path / "nope.abs")


def test_npz_round_trip_and_dispatch(tmp_path, xyz):
    path = tmp_path / "scan.npz"
    write_npz_range(path, xyz)
    np.testing.assert_array_equal(read_npz_range(path), xyz)
    np.testing.assert_array_equal(read_range(path), xyz)
    with pytest.raises(InputError, match="unknown range format"):
        read_range(tmp_path / "scan.ply")


def test_npz_bad_input(tmp_path):
    np.savez(tmp_path / "a.npz", depth=np.zeros((2, 2)))
    with pytest.raises(InputError, match="key 'xyz' missing"):
        read_npz_range(tmp_path / "a.npz")
    np.savez(tmp_path / "b.npz", xyz=np.zeros((2, 2)))
    with pytest.raises(InputError, match="expected an \\(H, W, 3\\) array"):
        read_npz_range(tmp_path / "b.npz")
    np.savez(tmp_path / "c.npz", xyz=np.full((2, 2, 3), np.inf))
    with pytest.raises(InputError, match="infinite"):
        read_npz_range(tmp_path / "c.npz")
    (tmp_path / "d.npz").write_text("not a zip")
    with pytest.raises(InputError, match="xyz: expected a NumPy .npz .*, not NumPy data"):
        read_npz_range(tmp_path / "d.npz")


def test_pts_round_trip_is_one_based(tmp_path):
    pts = np.random.default_rng(1).uniform(0, 100, (68, 2))
    path = tmp_path / "a.pts"
    write_pts(path, pts)
    lines = path.read_text().splitlines()
    assert lines[:3] == ["version: 1", "n_points: 68", "{"] and lines[-1] == "}"
    np.testing.assert_allclose([float(v) for v in lines[3].split()], pts[0] + 1.0, atol=1e-4)
    np.testing.assert_allclose(read_pts(path), pts, atol=1e-4)


def _pts_text(n, declared=None, extra=""):
    body = "\n".join(f"{i + 1}.0 {i + 2}.0" for i in range(n))
    return f"version: 1\nn_points: {declared or n}\n{{\n{body}\n{extra}}}\n"


@pytest.mark.parametrize(
    "text, match",
    [
        (_pts_text(67), "n_points: 67 points; accepted: 68 \\(iBUG-68\\) or 51"),
        (_pts_text(67, declared=68), "n_points says 68 but the list has 67"),
        (_pts_text(68).replace("5.0 6.0", "5.0 abc"), "point 5: non-numeric"),
        (_pts_text(68).replace("5.0 6.0", "5.0 nan"), "point 5: non-finite"),
        (_pts_text(68).replace("}\n", ""), "missing '}'"),
        ("version: 1\n{\n}\n", "'n_points' missing"),
    ],
)
def test_pts_bad_input(tmp_path, text, match):
    path = tmp_path / "bad.pts"
    path.write_text(text)
    with pytest.raises(InputError, match=match):
        read_pts(path)


def test_color_round_trip_and_errors(tmp_path):
    rgb = np.random.default_rng(2).integers(0, 256, (5, 6, 3), dtype=np.uint8)
    for name in ("c.png", "c.ppm"):
        write_color(tmp_path / name, rgb)
        np.testing.assert_array_equal(read_color(tmp_path / name), rgb)
    (tmp_path / "x.png").write_bytes(b"garbage")
    with pytest.raises(InputError, match="cannot decode"):
        read_color(tmp_path / "x.png")
    (tmp_path / "c.tiff").write_bytes(b"x")
    with pytest.raises(InputError, match="unknown image format"):
        read_color(tmp_path / "c.tiff")


def test_a_jpeg_cut_short_is_refused(tmp_path):
    """OpenCV decodes a JPEG cut short (a truncated copy or download) without an error, the
    missing rows filled grey: an RGB-D take's colour image cut to a third ran the whole
    pipeline, its landmarks detected on the grey (audit7). Refused; a whole JPEG reads."""
    rgb = np.random.default_rng(3).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    write_color(tmp_path / "c.jpg", rgb)
    assert read_color(tmp_path / "c.jpg").shape == rgb.shape
    data = (tmp_path / "c.jpg").read_bytes()
    (tmp_path / "cut.jpg").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"cut.jpg: color: the image is cut short"):
        read_color(tmp_path / "cut.jpg")


def test_a_jpeg_a_viewer_turns_is_read_as_stored_with_a_warning(tmp_path, caplog):
    """A phone's photo: its EXIF orientation has viewers turn it, OpenCV reads the pixels as
    stored. Read as stored (the range grid's order), with a warning naming the turn; before,
    without a word (audit finding 13). A JPEG without the tag reads quietly."""
    from PIL import Image

    rgb = np.random.default_rng(3).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    exif = Image.Exif()
    exif[274] = 6
    Image.fromarray(rgb).save(tmp_path / "phone.jpg", quality=95, exif=exif)
    Image.fromarray(rgb).save(tmp_path / "plain.jpg", quality=95)
    with caplog.at_level("WARNING", logger="scan2morph"):
        turned = read_color(tmp_path / "phone.jpg")
        plain = read_color(tmp_path / "plain.jpg")
    assert turned.shape == (48, 64, 3) and np.array_equal(turned, plain)
    assert [r.getMessage() for r in caplog.records] == [
        f"{tmp_path / 'phone.jpg'}: color: the JPEG's EXIF orientation has viewers show it "
        "turned 90 degrees clockwise; its pixels are read as stored, not turned: landmarks "
        "and UVs must be in the stored pixel order"
    ]
    # more pixels than Pillow's bomb limit (a 200 MP phone photo): read by OpenCV, no traceback
    monkey = pytest.MonkeyPatch()
    monkey.setattr(Image, "MAX_IMAGE_PIXELS", 100)
    try:
        assert np.array_equal(read_color(tmp_path / "phone.jpg"), plain)
    finally:
        monkey.undo()


def test_range_take_checks_sizes_and_landmarks(tmp_path):
    v, u = np.mgrid[0:20, 0:30].astype(np.float64)
    xyz = np.dstack([u, v, np.full_like(u, 600.0)])  # a plane (all zeros is a placeholder)
    write_abs(tmp_path / "s.abs", xyz)
    write_color(tmp_path / "ok.png", np.zeros((20, 30, 3), np.uint8))
    write_color(tmp_path / "big.png", np.zeros((21, 30, 3), np.uint8))
    pts = np.tile([[10.0, 10.0]], (68, 1))
    write_pts(tmp_path / "p.pts", pts)
    take = read_range_take(tmp_path / "s.abs", tmp_path / "ok.png", tmp_path / "p.pts")
    assert take.xyz.shape == (20, 30, 3) and take.landmarks.shape == (68, 2)
    with pytest.raises(InputError, match="big.png: color: image is 30x21 .* 30x20"):
        read_range_take(tmp_path / "s.abs", tmp_path / "big.png", tmp_path / "p.pts")
    pts[3] = [35.0, 5.0]
    write_pts(tmp_path / "q.pts", pts)
    with pytest.raises(InputError, match="q.pts: point 4 lies outside the 30x20 image"):
        read_range_take(tmp_path / "s.abs", tmp_path / "ok.png", tmp_path / "q.pts")
    write_abs(tmp_path / "empty.abs", np.full((20, 30, 3), np.nan))
    with pytest.raises(InputError, match="no valid pixel"):
        read_range_take(tmp_path / "empty.abs", tmp_path / "ok.png", tmp_path / "p.pts")


def test_a_text_files_bad_byte_is_named_by_its_line_bom_or_not(tmp_path):
    """The review: with the byte-order mark dropped the error's offset was the text's, not the
    file's, and named "line 1: byte 0x20" for a Latin-1 byte on line 2."""
    from scan2morph.io.text_file import utf8_text

    path = tmp_path / "lm.txt"
    path.write_bytes(b"\xef\xbb\xbf1 2 3\n\xe9 5 6\n")
    for bom in (True, False):
        with pytest.raises(InputError) as info:
            utf8_text(path, bom=bom)
        assert str(info.value) == (
            f"{path}: line 2: byte 0xe9 is not UTF-8 text (saved as Latin-1 or another code "
            "page?); expected UTF-8"
        )
    path.write_bytes(b"\xef\xbb\xbf1 2 3\n")
    assert utf8_text(path, bom=True) == "1 2 3\n"


def test_a_numpy_file_that_cannot_be_opened_is_one_line(tmp_path):
    """The review: opening the file to read its first bytes raised OSError as a traceback."""
    from scan2morph.io.numpy_file import check_numpy_file

    (tmp_path / "d.npz").mkdir()  # a folder where a file should be: open() fails
    with pytest.raises(InputError, match=r"d.npz: depth: cannot read: Is a directory"):
        check_numpy_file(tmp_path / "d.npz", "depth")
