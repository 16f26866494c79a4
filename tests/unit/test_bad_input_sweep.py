"""Bad input as a new user brings it (issue: bad-input sweep): each case one line naming the
file, the field and what was expected, where before it gave a traceback, a cryptic line or
silent garbage. Small files written here, read by the library's readers and the sheet."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from scan2morph.errors import InputError
from scan2morph.io import (
    RGBDIntrinsics,
    StereoCalibration,
    read_depth,
    read_landmarks3d,
    read_mesh,
    read_pts,
    read_rgbd_intrinsics,
    read_stereo_calibration,
    write_color,
    write_depth_png,
    write_pts,
    write_rgbd_intrinsics,
    write_stereo_calibration,
)
from scan2morph.io.check import take_file_problems
from scan2morph.io.rgbd import PinholeCamera
from scan2morph.sheet import read_sheet, validate_config
from tests.support.configs import repo_config
from tests.support.workflow_api import snakemake_dry_run

ROOT = Path(__file__).resolve().parents[2]
TETRA_V = np.array([[0.0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _one_line(exc: pytest.ExceptionInfo, source) -> str:
    text = str(exc.value)
    assert "\n" not in text and text.startswith(str(source))
    return text


def _obj(path: Path, vertices, faces) -> Path:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_good_tetrahedron_reads(tmp_path):
    mesh = read_mesh(_obj(tmp_path / "t.obj", TETRA_V, TETRA_F))
    assert len(mesh.faces) == 4


def test_a_mesh_with_a_nan_vertex_is_one_line_not_a_kdtree_traceback(tmp_path):
    vertices = TETRA_V.copy()
    vertices[2, 1] = np.nan
    path = _obj(tmp_path / "nan.obj", vertices, TETRA_F)
    with pytest.raises(InputError) as exc:
        read_mesh(path)
    assert _one_line(exc, path) == (
        f"{path}: vertices: 1 of 4 have a NaN or infinite coordinate (the first: vertex 3); "
        "expected finite numbers"
    )


def test_a_face_indexing_past_the_vertices_is_named(tmp_path):
    faces = TETRA_F.copy()
    faces[1, 2] = 9
    path = _obj(tmp_path / "past.obj", TETRA_V, faces)
    with pytest.raises(InputError, match="faces: a face refers to a vertex the file does not have"):
        read_mesh(path)


def test_an_obj_whose_first_vertex_follows_a_bom_is_refused_not_shifted(tmp_path):
    """Before: the BOM hid the first vertex line and trimesh dropped it: every face pointed one
    vertex on, read without a word when the last vertex was unused (here, the tetrahedron's
    faces landing on a stray vertex) and otherwise 'faces: a face refers to a vertex the file
    does not have'. A BOM before a comment line hides nothing and still reads."""
    vertices = np.r_[TETRA_V, [[50.0, 50.0, 50.0]]]  # a vertex no face uses
    path = _obj(tmp_path / "bom.obj", vertices, TETRA_F)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    with pytest.raises(InputError) as exc:
        read_mesh(path)
    assert _one_line(exc, path) == (
        f"{path}: mesh: the OBJ starts with a byte-order mark (BOM) before its first line "
        "'v 0.0 0.0 0.0', which hides that line from the reader; save it as UTF-8 without BOM"
    )
    path.write_bytes(b"\xef\xbb\xbf# exported\n" + path.read_bytes()[3:])
    assert np.array_equal(read_mesh(path).vertices[read_mesh(path).faces], TETRA_V[TETRA_F])
    # a hidden object or group name costs nothing either (the review: it was refused)
    path.write_bytes(b"\xef\xbb\xbfo Head\n" + path.read_bytes()[3:])
    assert np.array_equal(read_mesh(path).vertices[read_mesh(path).faces], TETRA_V[TETRA_F])


def test_an_ascii_ply_cut_short_is_refused_not_read_in_part(tmp_path):
    """Before: cut in its face list, an ASCII PLY read without a word with the faces there were
    (a face cut in half: half a face); cut in its vertices, 'no faces (... a point cloud?)' or,
    with vertex colours, trimesh's 'face colors incorrect shape!'."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=90.0)
    text = sphere.export(file_type="ply", encoding="ascii")
    head, body = text.split(b"end_header\n")
    lines = body.split(b"\n")
    cuts = {
        "faces.ply": (lines[:300], "300 data lines, expected 482 (162 vertex + 320 face)"),
        "vertices.ply": (lines[:100], "100 data lines, expected 482 (162 vertex + 320 face)"),
    }
    for name, (kept, said) in cuts.items():
        path = tmp_path / name
        path.write_bytes(head + b"end_header\n" + b"\n".join(kept))
        with pytest.raises(InputError) as exc:
            read_mesh(path)
        assert _one_line(exc, path) == (
            f"{path}: mesh: the file is shorter than its PLY header says (cut short?): {said}"
        )
    path = tmp_path / "last.ply"
    path.write_bytes(head + b"end_header\n" + b"\n".join(lines[:481]) + b"\n3 5")
    with pytest.raises(InputError) as exc:
        read_mesh(path)
    assert _one_line(exc, path).endswith(
        "mesh: the file's last face holds 1 of the 3 vertex indices it says: the file looks cut "
        "short"
    )
    path.write_bytes(text)
    assert len(read_mesh(path).faces) == 320


def test_an_obj_with_decimal_commas_names_its_first_vertex_line(tmp_path):
    """Before: trimesh's 'mesh: cannot read: string or file could not be read to its end due to
    unmatched data'."""
    path = _obj(tmp_path / "comma.obj", TETRA_V + 0.5, TETRA_F)
    path.write_text("# exported, Gr\u00f6\u00dfe 1,5\n" + path.read_text().replace(".", ","))
    with pytest.raises(InputError) as exc:
        read_mesh(path)
    assert _one_line(exc, path) == (
        f"{path}: vertex line 2: 'v 0,5 0,5 0,5' has decimal commas; expected numbers with "
        "decimal points (an exporter set to a European locale?)"
    )


@pytest.mark.parametrize("name", ["z.glb", "z.ply", "z.obj"])
def test_an_empty_mesh_file_says_so(tmp_path, name):
    (tmp_path / name).write_bytes(b"")
    with pytest.raises(InputError) as exc:
        read_mesh(tmp_path / name)
    assert _one_line(exc, tmp_path / name).endswith(
        "mesh: the file is empty (0 bytes; expected an OBJ, PLY or glTF/GLB)"
    )


# --- the sheet --------------------------------------------------------------------------------
HEADER = "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor\tlandmarks\n"
ROW = "a\tneutral\tneutral\tneutral\trange\tn.abs\tn.png\tn.pts\n"


def test_a_row_with_one_cell_too_many_is_refused_not_shifted(tmp_path):
    """pandas took the first column of such a sheet for its index: every cell moved one column
    to the left (subject 'neutral', modality 'n.abs') and the problems named the wrong ones."""
    path = tmp_path / "s.tsv"
    path.write_text(HEADER + ROW.rstrip("\n") + "\tn2.pts\n")
    with pytest.raises(InputError) as exc:
        read_sheet(path)
    assert _one_line(exc, path) == (
        f"{path}: row 2: 9 cells but the header has 8 columns (a tab too many?; the extra: "
        "'n2.pts')"
    )


def test_trailing_tabs_are_empty_cells_on_any_row(tmp_path):
    """A trailing tab (as spreadsheets export) on the first row shifted the sheet; on a later
    row it stopped the run with pandas' two-line 'Expected 8 fields in line 3, saw 9'."""
    path = tmp_path / "s.tsv"
    path.write_text(
        HEADER + ROW.rstrip("\n") + "\t\n" + ROW.replace("a\t", "b\t", 1).rstrip() + "\t\t\n"
    )
    sheet = read_sheet(path)
    assert list(sheet["subject"]) == ["a", "b"]
    assert list(sheet["modality"]) == ["range", "range"]
    assert sheet.loc[1, "landmarks"] == str(tmp_path / "n.pts")


def test_a_hash_inside_a_path_is_kept_and_one_starting_a_cell_is_a_comment(tmp_path):
    """Before: pandas' comment='#' cut 'take#2.abs' to 'take' and dropped the row's colour and
    landmarks after it, silently (the problem named a file 'take' that nobody wrote)."""
    path = tmp_path / "s.tsv"
    row = ROW.replace("n.abs", "take#2.abs").rstrip("\n") + "\t# clicked twice\n"
    path.write_text("# my sheet\n" + HEADER + "  # a commented-out row\n" + row)
    sheet = read_sheet(path)
    assert len(sheet) == 1
    assert sheet.loc[0, "xyz"] == str(tmp_path / "take#2.abs")
    assert sheet.loc[0, "landmarks"] == str(tmp_path / "n.pts")


def test_a_path_from_the_home_folder(tmp_path, monkeypatch):
    """Before: '~/scans/n.abs' was taken relative to the sheet ('file not found: <sheet
    folder>/~/scans/n.abs')."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    path = tmp_path / "s.tsv"
    path.write_text(HEADER + ROW.replace("n.abs", "~/scans/n.abs"))
    assert read_sheet(path).loc[0, "xyz"] == str(tmp_path / "home" / "scans" / "n.abs")


@pytest.mark.parametrize("sep, looks", [(",", "commas"), ("  ", "spaces"), (" ", "spaces")])
def test_a_sheet_separated_by_commas_or_spaces_is_named(tmp_path, sep, looks):
    path = tmp_path / "s.tsv"
    path.write_text((HEADER + ROW).replace("\t", sep))
    with pytest.raises(InputError) as exc:
        read_sheet(path)
    assert _one_line(exc, path).endswith(
        "expected a tab-separated sheet (this one looks separated by commas or spaces)"
    )
    assert f"{path}: header: no tab between the column names ('subject{sep}take" in str(exc.value)


# --- the stereo calibration -------------------------------------------------------------------
K = [[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]]
K1_DATA = "data: [ 800., 0., 319.5, 0., 800., 239.5, 0., 0., 1. ]"


@pytest.fixture
def calibration(tmp_path):
    calib = StereoCalibration(K, np.zeros(5), K, np.zeros(5), np.eye(3), [-60.0, 0, 0])
    write_stereo_calibration(tmp_path / "good.yaml", calib)
    text = (tmp_path / "good.yaml").read_text()
    assert K1_DATA in text
    return text


@pytest.mark.parametrize(
    "edit, problem",
    [
        (
            lambda t: t.replace("319.5", "abc", 1),
            "K1: expected an !!opencv-matrix with rows, cols, dt and rows x cols numbers in data; "
            "got the non-numeric entry 'abc'",
        ),
        (
            lambda t: t.replace(" 0., 0., 1. ]", " 0., 0. ]", 1),
            "K1: expected an !!opencv-matrix with rows, cols, dt and rows x cols numbers in data; "
            "got rows 3 x cols 3 but 8 numbers",
        ),
        (
            lambda t: t.replace("   " + K1_DATA + "\n", "", 1),
            "K1: expected an !!opencv-matrix with rows, cols, dt and rows x cols numbers in data; "
            "data missing (a truncated file?)",
        ),
        (
            lambda t: "\ufeff" + t,
            "not an OpenCV FileStorage calibration (expected a YAML file with a '%YAML:1.0' header "
            "and the matrices K1 D1 K2 D2 R T); it starts with a byte-order mark (BOM): save it "
            "as UTF-8 without BOM",
        ),
        (
            lambda t: t.replace("   rows: 3", "\trows: 3", 1),
            "; line 5 is indented with a tab (YAML: spaces only)",
        ),
    ],
)
def test_a_hand_edited_calibration_says_what_is_wrong(tmp_path, calibration, edit, problem):
    """Before: 'K1: not an !!opencv-matrix' for the first three, no hint for the last two."""
    path = tmp_path / "bad.yaml"
    path.write_text(edit(calibration), encoding="utf-8")
    with pytest.raises(InputError) as exc:
        read_stereo_calibration(path)
    assert _one_line(exc, path).endswith(problem)


# --- RGB-D and mesh side files ----------------------------------------------------------------
def _intrinsics(tmp_path, **extra) -> Path:
    depth = PinholeCamera(np.array(K), np.zeros(5), (640, 480))
    write_rgbd_intrinsics(
        tmp_path / "i.yaml", RGBDIntrinsics(depth, depth, np.eye(3), np.zeros(3), 1.0)
    )
    doc = yaml.safe_load((tmp_path / "i.yaml").read_text())
    doc.update(extra)
    (tmp_path / "i.yaml").write_text(yaml.safe_dump(doc))
    return tmp_path / "i.yaml"


def test_a_misspelt_intrinsics_key_is_refused_not_ignored(tmp_path):
    """Before: 'distorsion' was ignored and the take resampled without its distortion."""
    assert read_rgbd_intrinsics(_intrinsics(tmp_path)).depth.size == (640, 480)
    path = _intrinsics(tmp_path, distorsion=[0.1, 0, 0, 0, 0])
    with pytest.raises(InputError) as exc:
        read_rgbd_intrinsics(path)
    assert _one_line(exc, path) == (
        f"{path}: distorsion: unknown key (known: width, height, fx, fy, cx, cy, depth_scale_mm, "
        "distortion, color)"
    )
    path = _intrinsics(tmp_path, color={"width": 640, "height": 480, "fx": 800.0, "fy": 800.0,
                                        "cx": 319.5, "cy": 239.5, "t": [15.0, 0, 0]})  # fmt: skip
    with pytest.raises(InputError, match=r"i.yaml: color.t: unknown key \(known: .*, R, T\)"):
        read_rgbd_intrinsics(path)


def test_a_boolean_depth_array_names_its_type(tmp_path):
    """Before: 'expected an (H, W) number array, got (120, 160)': the shape it asked for."""
    np.save(tmp_path / "d.npy", np.ones((120, 160), bool))
    with pytest.raises(InputError) as exc:
        read_depth(tmp_path / "d.npy")
    assert _one_line(exc, tmp_path / "d.npy").endswith(
        "depth: expected an (H, W) number array, got (120, 160) bool"
    )


def test_an_8_bit_depth_array_is_refused_and_a_float16_one_named(tmp_path, caplog):
    """Before: an 8-bit array (256 levels; an 8-bit PNG is refused) and a float16 one (0.5 mm
    steps at 1 m) were read without a word (audit finding 18)."""
    depth = np.full((120, 160), 1000.0)
    np.save(tmp_path / "d8.npy", np.full((120, 160), 200, np.uint8))
    with pytest.raises(InputError) as exc:
        read_depth(tmp_path / "d8.npy")
    assert _one_line(exc, tmp_path / "d8.npy").endswith(
        "depth: expected 16-bit or wider integers or float32/float64, got uint8"
    )
    np.save(tmp_path / "d16.npy", (depth + 0.2).astype(np.float16))
    with caplog.at_level("WARNING", logger="scan2morph"):
        read = read_depth(tmp_path / "d16.npy")
    assert np.all(read == 1000.0)  # 1000.2 read as 1000: the steps the warning names
    assert [r.getMessage() for r in caplog.records] == [
        f"{tmp_path / 'd16.npy'}: depth: float16 values keep 11 significant bits (steps of "
        "1/2048 to 1/1024 of the value, 0.5-1 mm at 1 m): the surface is read quantised; save "
        "the depth as float32 or 16-bit integers"
    ]
    caplog.clear()
    np.save(tmp_path / "d32.npy", depth.astype(np.float32))
    with caplog.at_level("WARNING", logger="scan2morph"):
        read_depth(tmp_path / "d32.npy")
    assert not caplog.records


def test_a_file_that_is_not_the_numpy_format_its_suffix_names(tmp_path):
    """Before: a text file named .npz or .npy was 'This file contains pickled (object) data. If
    you trust the file you can load it unsafely using the `allow_pickle=` keyword argument',
    an .npy named .npz 'object does not support the context manager protocol', and an .npz
    named .npy 'expected an (H, W) number array, got (1,) <U5' (the array of its key names)."""
    from scan2morph.io import read_npz_range

    depth = np.ones((12, 16))
    (tmp_path / "text.npz").write_text("hello")
    np.save(tmp_path / "one.npy", depth)
    (tmp_path / "one.npz").write_bytes((tmp_path / "one.npy").read_bytes())
    np.savez(tmp_path / "two.npz", depth=depth)
    (tmp_path / "two.npy").write_bytes((tmp_path / "two.npz").read_bytes())
    (tmp_path / "empty.npy").write_bytes(b"")
    npz, npy = "a NumPy .npz (a zip archive of named arrays)", "a NumPy .npy array"
    cases = [
        (read_npz_range, "text.npz", f"xyz: expected {npz}, got a file starting with b'hello', "
         "not NumPy data"),
        (read_npz_range, "one.npz", f"xyz: expected {npz}, got {npy} named .npz"),
        (read_depth, "one.npz", f"depth: expected {npz}, got {npy} named .npz"),
        (read_depth, "two.npy", f"depth: expected {npy}, got {npz} named .npy"),
        (read_depth, "empty.npy", f"depth: expected {npy}, got an empty file (0 bytes)"),
    ]  # fmt: skip
    for reader, name, problem in cases:
        with pytest.raises(InputError) as exc:
            reader(tmp_path / name)
        assert _one_line(exc, tmp_path / name) == f"{tmp_path / name}: {problem}"
    assert read_depth(tmp_path / "one.npy").shape == read_depth(tmp_path / "two.npz").shape


def test_a_depth_folder_copied_from_a_mac_reads_without_its_hidden_files(tmp_path):
    """Before: macOS's '._f0.png' beside each frame (its metadata, on a USB stick or a network
    share) was read as a frame: 'depth: cannot decode the PNG (corrupt or not an image)'."""
    from scan2morph.io.depth_image import depth_frame_paths, read_depth_frames

    folder = tmp_path / "frames"
    folder.mkdir()
    write_depth_png(folder / "f0.png", np.full((12, 16), 600.0))
    (folder / "._f0.png").write_bytes(b"\x00\x05\x16\x07\x00\x02\x00\x00Mac OS X")
    assert depth_frame_paths(folder) == [folder / "f0.png"]
    assert [f.shape for f in read_depth_frames(str(folder))] == [(12, 16)]


def test_a_text_file_saved_as_latin1_names_the_line_and_byte(tmp_path):
    """Before: Python's codec message, "cannot read as text: 'utf-8' codec can't decode byte
    0xe4 in position 23: invalid continuation byte" (the intrinsics: "cannot read as YAML: ...")."""
    points = np.tile([[50.0, 60.0]], (68, 1))
    write_pts(tmp_path / "p.pts", points)
    pts = tmp_path / "p.pts"
    pts.write_bytes(pts.read_bytes() + "# Gesicht gedr\xfcckt\n".encode("latin-1"))
    xyz = tmp_path / "l.txt"
    xyz.write_bytes("# Kopf von J\xfcrgen\n".encode("latin-1") + b"1 2 3\n" * 68)
    intrinsics = tmp_path / "i.yaml"
    intrinsics.write_bytes("# Kamera vorn \xe4\nwidth: 160\n".encode("latin-1"))
    said = "is not UTF-8 text (saved as Latin-1 or another code page?); expected UTF-8"
    for reader, path, where in (
        (read_pts, pts, "line 73: byte 0xfc"),
        (read_landmarks3d, xyz, "line 1: byte 0xfc"),
        (read_rgbd_intrinsics, intrinsics, "line 1: byte 0xe4"),
    ):
        with pytest.raises(InputError) as exc:
            reader(path)
        assert _one_line(exc, path) == f"{path}: {where} {said}"


def test_3d_landmarks_saved_with_a_bom_read_like_a_pts_file(tmp_path):
    """Before: 'line 1: expected 'x y z' numbers, got '\\ufeff1 2 3'' (a .pts with a BOM read)."""
    rows = np.arange(68 * 3, dtype=float).reshape(68, 3)
    text = "".join(f"{x} {y} {z}\r\n" for x, y, z in rows)
    (tmp_path / "l.txt").write_text("\ufeff" + text, encoding="utf-8", newline="")
    np.testing.assert_array_equal(read_landmarks3d(tmp_path / "l.txt"), rows)


def _rgbd_files(tmp_path, depth, color_size=(64, 48)) -> dict:
    camera = PinholeCamera(
        np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]]), np.zeros(5), (64, 48)
    )
    write_rgbd_intrinsics(
        tmp_path / "i.yaml", RGBDIntrinsics(camera, camera, np.eye(3), np.zeros(3), 1.0)
    )
    write_depth_png(tmp_path / "d.png", depth)
    write_color(tmp_path / "c.png", np.zeros((color_size[1], color_size[0], 3), np.uint8))
    return {
        "depth": tmp_path / "d.png",
        "color": tmp_path / "c.png",
        "intrinsics": tmp_path / "i.yaml",
    }


def test_the_check_lists_an_rgbd_takes_size_and_data_problems(tmp_path):
    """Before, the subject's check passed an all-zero depth frame and a colour image of another
    size than its intrinsics: the take failed only at its ingest, after the check had said the
    subject's files were fine."""
    good = np.full((48, 64), 600, np.uint16)
    assert take_file_problems("rgbd", _rgbd_files(tmp_path, good)) == []
    files = _rgbd_files(tmp_path, np.zeros((48, 64), np.uint16))
    assert take_file_problems("rgbd", files) == [
        f"{files['depth']}: depth: no pixel with data (all 0 or NaN)"
    ]
    files = _rgbd_files(tmp_path, good, color_size=(128, 96))
    assert take_file_problems("rgbd", files) == [
        f"{files['intrinsics']}: color.width/color.height: 64x48 but the color image c.png is "
        "128x96 (WxH); are these the intrinsics of this color camera?"
    ]


@pytest.mark.parametrize(
    "text, problem",
    [
        (
            "width: 64\ncolor:\n\twidth: 64\n",
            "line 3: found a tab (YAML indents with spaces) that cannot start any token",
        ),
        ("width: [64, 48\n", "line 2: expected ',' or ']', but got '<stream end>'"),
    ],
)
def test_intrinsics_that_are_not_yaml_name_the_line(tmp_path, text, problem):
    """Before: PyYAML's context alone, 'cannot read as YAML: while scanning for the next token'."""
    (tmp_path / "i.yaml").write_text(text)
    with pytest.raises(InputError) as exc:
        read_rgbd_intrinsics(tmp_path / "i.yaml")
    assert (
        _one_line(exc, tmp_path / "i.yaml")
        == f"{tmp_path / 'i.yaml'}: cannot read as YAML: {problem}"
    )


# --- landmark files of the other kind ---------------------------------------------------------
def test_a_bare_list_of_points_or_an_empty_file_as_pts(tmp_path):
    """Before: "header line '60.95 56.48': expected 'key: value' or '{'" and "missing '{' that
    opens the point list"."""
    path = tmp_path / "bare.pts"
    path.write_text("".join(f"{x} {x + 1}\n" for x in range(68)))
    with pytest.raises(InputError) as exc:
        read_pts(path)
    assert _one_line(exc, path) == (
        f"{path}: header: '0 1' is a point, but an iBUG .pts starts with a header ('version: 1', "
        "'n_points: 68', '{'; the points, then '}')"
    )
    (tmp_path / "empty.pts").write_text("\n")
    with pytest.raises(InputError, match=r"empty.pts: the file is empty \(expected an iBUG .pts"):
        read_pts(tmp_path / "empty.pts")


def test_a_2d_pts_given_for_a_mesh_take_is_named(tmp_path):
    write_pts(tmp_path / "l.pts", np.zeros((68, 2)))
    with pytest.raises(InputError) as exc:
        read_landmarks3d(tmp_path / "l.pts")
    assert _one_line(exc, tmp_path / "l.pts").endswith(
        "line 1: expected 'x y z' numbers, got 'version: 1' (an iBUG .pts of 2D image points? a "
        "mesh take needs 3D points on the mesh)"
    )


@pytest.mark.slow  # starts Snakemake: not in make test-fast
def test_an_empty_sheet_without_the_synthetic_cohort_stops_the_run_in_one_line(tmp_path):
    """Before: Snakemake ran its 'all' rule over no subject and exited 0, saying nothing."""
    (tmp_path / "s.tsv").write_text(HEADER + "# a\tneutral\tneutral\tneutral\trange\tn.abs\n")
    (tmp_path / "my.yaml").write_text("subjects: s.tsv\nsynthetic: {subjects: 0}\n")
    status, lines = snakemake_dry_run(tmp_path, "my.yaml")
    assert status != 0
    assert len(lines) <= 3
    assert lines[-1] == (
        "Error: s.tsv: no takes: the sheet has no rows (only its header or comments) and "
        "synthetic.subjects is 0, so there is nothing to run"
    )


def test_a_gltf_whose_buffer_file_is_missing_names_it(tmp_path):
    """Before: 'mesh: cannot read: gltf_buffer_0.bin' (trimesh's FileNotFoundError)."""
    import trimesh

    files = trimesh.Trimesh(TETRA_V, TETRA_F, process=False).export(file_type="gltf")
    for name, data in files.items():
        (tmp_path / ("m.gltf" if name == "model.gltf" else name)).write_bytes(data)
    assert len(read_mesh(tmp_path / "m.gltf").faces) == 4
    buffers = sorted(p.name for p in tmp_path.glob("*.bin"))
    for name in buffers:
        (tmp_path / name).unlink()
    with pytest.raises(InputError) as exc:
        read_mesh(tmp_path / "m.gltf")
    assert _one_line(exc, tmp_path / "m.gltf").endswith(
        f"mesh: the file names '{buffers[0]}' (a buffer or image), which is missing"
    )


def test_a_corrupt_texture_is_not_called_missing(tmp_path):
    """Before: '... (the material names 'tex.png', which is missing)' for a file that is there."""
    (tmp_path / "t.mtl").write_text("newmtl m\nmap_Kd tex.png\n")
    (tmp_path / "tex.png").write_text("not an image")
    lines = ["mtllib t.mtl", "usemtl m"] + [f"v {x} {y} {z}" for x, y, z in TETRA_V]
    lines += ["vt 0 0", "vt 1 0", "vt 0 1", "vt 1 1"]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in TETRA_F]
    (tmp_path / "m.obj").write_text("\n".join(lines) + "\n")
    with pytest.raises(
        InputError, match=r"names 'tex.png', which cannot be read as an image \(corrupt\?\)\)"
    ):
        read_mesh(tmp_path / "m.obj")
    (tmp_path / "tex.png").unlink()
    with pytest.raises(InputError, match=r"names 'tex.png', which is missing\)"):
        read_mesh(tmp_path / "m.obj")


def test_a_nan_in_the_config_is_refused_naming_its_key():
    """Before: '.nan' passed the schema's 'number' and every comparison with the threshold
    failed silently (min_confidence .nan: no take ever warned of a low confidence)."""
    config = repo_config()
    validate_config(copy.deepcopy(config), ROOT / "schemas" / "config.schema.yaml")
    config["landmarks"]["min_confidence"] = float("nan")
    with pytest.raises(InputError) as exc:
        validate_config(config, ROOT / "schemas" / "config.schema.yaml")
    assert str(exc.value) == "config: landmarks.min_confidence: expected a number, got nan"


def _stereo_pair(tmp_path, right_shift=3):
    """A small textured pair (64 x 48) and a calibration for it, written as a user brings them."""
    rng = np.random.default_rng(1)
    left = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    write_color(tmp_path / "l.png", left)
    write_color(tmp_path / "r.png", np.roll(left, right_shift, axis=1))
    k = [[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]]
    calib = StereoCalibration(k, np.zeros(5), k, np.zeros(5), np.eye(3), [-60.0, 0, 0])
    write_stereo_calibration(tmp_path / "c.yaml", calib)
    return {
        "left": tmp_path / "l.png",
        "right": tmp_path / "r.png",
        "calibration": tmp_path / "c.yaml",
    }


def test_one_image_given_twice_as_a_stereo_pair(tmp_path):
    """Before: the pair went to the stereo matching, which refused it as '2.30% of the left pixels
    were matched (floor 5%); check that left and right belong to this calibration, ...'."""
    files = _stereo_pair(tmp_path)
    assert take_file_problems("stereo", files) == []
    files["right"] = files["left"]
    assert take_file_problems("stereo", files) == [
        f"{files['left']}: right: the same image as the left l.png (one file given twice?); "
        "expected the second camera's view"
    ]


def test_a_corrupt_stereo_image_is_named_by_its_column(tmp_path):
    """Before: a corrupt right (or left) image was reported as 'color: cannot decode the
    image', whichever column named it (audit finding 12)."""
    from scan2morph.io.take import read_stereo_take

    files = _stereo_pair(tmp_path)
    for column in ("left", "right"):
        good = files[column].read_bytes()
        files[column].write_bytes(b"not a png")
        problem = f"{files[column]}: {column}: cannot decode the image (corrupt or not an image)"
        assert take_file_problems("stereo", files) == [problem]
        with pytest.raises(InputError) as exc:
            read_stereo_take(files["left"], files["right"], files["calibration"], None)
        assert str(exc.value) == problem
        files[column].write_bytes(good)


def test_a_calibration_of_another_image_size_is_named_by_its_principal_point(tmp_path):
    """Before (a calibration without image_width/height): 'calibration: expected views that can
    share a surface at 200-5000 mm, got rectified views that do not', after rectifying."""
    files = _stereo_pair(tmp_path)
    calib = read_stereo_calibration(files["calibration"])
    k = calib.K1 * [[4], [4], [1]]  # the rig's calibration at 256 x 192
    write_stereo_calibration(
        files["calibration"], StereoCalibration(k, calib.D1, k, calib.D2, calib.R, calib.T)
    )
    assert take_file_problems("stereo", files) == [
        f"{files['calibration']}: K1: the principal point (126, 94) px lies outside the 64x48 "
        "images; is this the calibration of this camera pair, at this image size?"
    ]


def test_a_sheet_in_utf16_reads_and_one_in_latin1_or_xlsx_is_named(tmp_path):
    """Before: "not a tab-separated sheet: 'utf-8' codec can't decode byte 0xff in position 0:
    invalid start byte" for all three (a spreadsheet's "Unicode text" export is UTF-16)."""
    path = tmp_path / "s.tsv"
    path.write_bytes((HEADER + ROW).encode("utf-16"))
    assert list(read_sheet(path)["modality"]) == ["range"]
    path.write_bytes((HEADER + ROW.replace("n.png", "café.png")).encode("latin-1"))
    with pytest.raises(InputError) as exc:
        read_sheet(path)
    assert _one_line(exc, path) == (
        f"{path}: line 2: byte 0xe9 is not UTF-8 text (a sheet saved in another encoding?); "
        "save it as UTF-8"
    )
    path.write_bytes(b"PK\x03\x04\x14\x00\x06\x00")
    with pytest.raises(InputError, match=r"s.tsv: a zip file \(an .xlsx or .ods spreadsheet\?\)"):
        read_sheet(path)
