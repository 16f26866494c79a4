"""Optional landmark files: a sheet without them, 51-point files, a mesh take without them
(its camera found from the surface alone), and the counts that are refused."""

from __future__ import annotations

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.io import read_pts, write_pts
from scan2morph.io.landmarks import JAWLINE, as_ibug68, complete
from scan2morph.io.mesh_scan import read_landmarks3d, read_mesh_take
from scan2morph.sheet import input_roles, read_sheet, subject_problems, synthetic_rows
from scan2morph.synth.mesh_scan import make_mesh_take, write_landmarks3d, write_mesh_take

TINY_CAMERA = dict(width=320, height=240)
JAW = np.asarray(JAWLINE) - 1


def _points(n: int) -> np.ndarray:
    rng = np.random.default_rng(n)
    return rng.uniform(10, 300, size=(n, 2))


def test_a_51_point_pts_file_gives_68_rows_with_the_jawline_missing(tmp_path):
    inner = _points(51)
    write_pts(tmp_path / "inner.pts", inner)
    got = read_pts(tmp_path / "inner.pts")
    assert got.shape == (68, 2)
    assert np.isnan(got[JAW]).all()
    np.testing.assert_allclose(got[17:], inner, atol=1e-4)
    assert not complete(got)
    write_pts(tmp_path / "all.pts", _points(68))
    assert complete(read_pts(tmp_path / "all.pts"))


@pytest.mark.parametrize("count", [0, 17, 50, 52, 67, 69, 98])
def test_other_counts_are_refused_naming_the_accepted_ones(tmp_path, count):
    write_pts(tmp_path / "bad.pts", _points(count)) if count else None
    if not count:
        (tmp_path / "bad.pts").write_text("version: 1\nn_points: 0\n{\n}\n")
    with pytest.raises(InputError, match=r"bad\.pts: n_points: .* accepted: 68 \(iBUG-68\) or 51"):
        read_pts(tmp_path / "bad.pts")
    lines = "\n".join(f"{x} {y} 1.0" for x, y in _points(count)) + "\n"
    (tmp_path / "bad.txt").write_text("# x y z\n" + lines)
    with pytest.raises(InputError, match=r"bad\.txt: got .* accepted: 68 \(iBUG-68\) or 51"):
        read_landmarks3d(tmp_path / "bad.txt")


@pytest.mark.parametrize("name", ["car.pts", "car.xyz"])
def test_the_record_of_a_take_left_out_given_back_says_what_it_is(tmp_path, name):
    """The file the pipeline writes for a take left out at its landmarks, given back in the
    sheet as the docs suggest for every take's points: it holds none, and says so (it was
    refused as a .pts without its '{')."""
    from scan2morph.io.landmarks import LEFT_OUT

    path = tmp_path / name
    path.write_text(f"{LEFT_OUT}car left out at landmarks: s1/car: face too small\n")
    read = read_pts if name.endswith(".pts") else read_landmarks3d
    with pytest.raises(
        InputError,
        match=rf"{name}: the pipeline's record of a take left out at its landmarks \(car left "
        r"out at landmarks: s1/car: face too small\), with no points to give back: leave the "
        r"sheet's landmarks cell empty to detect them again, or give clicked ones",
    ):
        read(path)


def test_a_mesh_takes_3d_points_given_for_an_image_take_say_so(tmp_path):
    """An .xyz (lines 'x y z') given where a .pts belongs: the message says which file to give."""
    path = tmp_path / "car.xyz"
    path.write_text("".join(f"{x} {y} 1000.5\n" for x, y in _points(68)))
    with pytest.raises(InputError, match=r"is a point.*3D points 'x y z' are for a mesh take"):
        read_pts(path)
    (tmp_path / "car2.pts").write_text("".join(f"{x} {y}\n" for x, y in _points(68)))
    with pytest.raises(InputError, match=r"is a point, but an iBUG .pts starts with") as plain:
        read_pts(tmp_path / "car2.pts")
    assert "mesh take" not in str(plain.value)  # 2D points: no word of mesh takes


def test_as_ibug68_keeps_a_full_set_and_pads_an_inner_one():
    full = _points(68)
    assert as_ibug68(full) is not None and np.array_equal(as_ibug68(full), full)
    padded = as_ibug68(_points(51))
    assert padded.shape == (68, 2) and np.isnan(padded[:17]).all()
    assert np.isfinite(padded[17:]).all()


def _sheet(tmp_path, header: str, rows: list[str]):
    for name in ("n.abs", "n.png", "n.pts", "c.abs", "c.png"):
        (tmp_path / name).write_text("x")
    path = tmp_path / "sheet.tsv"
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def test_a_sheet_without_a_landmarks_column_reads_and_has_no_problem(tmp_path):
    path = _sheet(
        tmp_path,
        "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor",
        ["s\tn\tneutral\tneutral\trange\tn.abs\tn.png", "s\tc\tviseme\tcar\trange\tc.abs\tc.png"],
    )
    sheet = read_sheet(path)
    assert list(sheet["landmarks"]) == ["", ""]
    assert subject_problems(sheet) == {"s": []}
    assert input_roles(sheet.loc[0]) == ["xyz", "color"]


def test_a_mixed_sheet_keeps_its_clicks_where_given(tmp_path):
    path = _sheet(
        tmp_path,
        "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor\tlandmarks",
        [
            "s\tn\tneutral\tneutral\trange\tn.abs\tn.png\tn.pts",
            "s\tc\tviseme\tcar\trange\tc.abs\tc.png\t",
        ],
    )
    sheet = read_sheet(path)
    assert subject_problems(sheet) == {"s": []}
    assert input_roles(sheet.loc[0]) == ["xyz", "color", "landmarks"]
    assert input_roles(sheet.loc[1]) == ["xyz", "color"]
    # a landmark file named but absent is still the take's problem, naming the column
    (tmp_path / "n.pts").unlink()
    problems = subject_problems(read_sheet(path))["s"]
    assert len(problems) == 1 and "column 'landmarks': file not found" in problems[0]


def test_the_synthetic_cohort_withholds_its_landmarks_on_request():
    takes = [{"take": "neutral", "kind": "neutral", "label": "neutral"}]
    clicked = synthetic_rows(1, "s", takes, "root")
    detect = synthetic_rows(1, "s", takes, "root", landmarks="detect")
    assert clicked.loc[0, "landmarks"] == "root/s01/neutral.pts"
    assert detect.loc[0, "landmarks"] == ""
    assert input_roles(detect.loc[0]) == ["xyz", "color"]


@pytest.fixture(scope="module")
def mesh_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("mesh")
    scan = make_mesh_take("s1", "she", "viseme", "she", seed=3)
    files = (d / "s.ply", d / "s.txt", d / "t.npz")
    write_mesh_take(scan, *files)
    return scan, files


def _read_only(take):
    for a in (take.xyz, take.color, take.landmarks, take.K, take.pose):
        if a is not None:
            a.setflags(write=False)
    return take


@pytest.fixture(scope="module")
def surface_take(mesh_files):
    """The scan read without landmarks (its camera from the surface alone); read-only, shared."""
    _, (ply, _, _) = mesh_files
    return _read_only(read_mesh_take(ply, None, None, TINY_CAMERA))


@pytest.fixture(scope="module")
def landmark_take(mesh_files):
    """The scan read with its true landmark file; read-only, shared."""
    _, (ply, txt, _) = mesh_files
    return _read_only(read_mesh_take(ply, None, txt, TINY_CAMERA))


def test_a_mesh_take_without_landmarks_is_rendered_upright_and_frontal(
    mesh_files, surface_take, landmark_take
):
    """The surface-only camera against the landmark camera of the same scan: the face upright
    (eyes above the mouth, the subject's right eye on the image's left), centred, the same size
    within a few per cent, the view direction the same."""
    _, (_, txt, _) = mesh_files
    free, with_lm = surface_take, landmark_take
    assert free.landmarks is None
    lm3 = read_landmarks3d(txt)
    cam = lm3 @ free.pose[:3, :3].T + free.pose[:3, 3]
    px = cam[:, :2] / cam[:, 2:] * np.diag(free.K)[:2] + free.K[:2, 2]
    eyes = px[[36, 45]].mean(axis=0)
    mouth = px[[48, 54]].mean(axis=0)
    assert eyes[1] < mouth[1] - 0.1 * TINY_CAMERA["height"]  # eyes above the mouth
    assert px[36, 0] < px[45, 0]  # iBUG 37 (subject's right eye) on the image's left
    centre = px.mean(axis=0)
    size = np.array([TINY_CAMERA["width"], TINY_CAMERA["height"]])
    assert (np.abs(centre - (size - 1) / 2) < 0.1 * size).all()
    # the same view direction as the landmark camera, within the surface tip's difference
    cos = free.pose[2, :3] @ with_lm.pose[2, :3]
    assert np.degrees(np.arccos(min(cos, 1.0))) < 5.0
    ratio = free.K[0, 0] / with_lm.K[0, 0]
    assert 0.85 < ratio < 1.15
    # the rendered pixels are the same surface (both cameras see the face)
    assert np.isfinite(free.xyz).all(axis=-1).mean() > 0.3


@pytest.mark.parametrize("turn", [1, 2, 3])
def test_the_surface_camera_finds_up_whatever_the_frame(mesh_files, tmp_path, turn):
    """The mesh turned about its view axis by 90-270 degrees: the image stays upright (as the
    unturned mesh's in the test above)."""
    import trimesh

    scan, _ = mesh_files
    axis = scan["landmarks"][30] - scan["landmarks"][:, :].mean(axis=0)
    rot = trimesh.transformations.rotation_matrix(np.pi / 2 * turn, axis / np.linalg.norm(axis))
    v = scan["vertices"] @ rot[:3, :3].T
    lm3 = scan["landmarks"] @ rot[:3, :3].T
    trimesh.Trimesh(v, scan["faces"], process=False).export(tmp_path / "r.ply")
    take = read_mesh_take(tmp_path / "r.ply", None, None, TINY_CAMERA)
    cam = lm3 @ take.pose[:3, :3].T + take.pose[:3, 3]
    px = cam[:, :2] / cam[:, 2:] * np.diag(take.K)[:2] + take.K[:2, 2]
    assert px[[36, 45], 1].mean() < px[[48, 54], 1].mean() - 20
    assert px[36, 0] < px[45, 0]


def test_a_51_point_mesh_landmark_file_projects_its_points_and_leaves_the_jaw(mesh_files, tmp_path):
    scan, (ply, _, _) = mesh_files
    write_landmarks3d(tmp_path / "inner.txt", scan["landmarks"][17:])
    take = read_mesh_take(ply, None, tmp_path / "inner.txt", TINY_CAMERA)
    assert take.landmarks.shape == (68, 2)
    assert np.isnan(take.landmarks[JAW]).all() and np.isfinite(take.landmarks[17:]).all()
    # the inner points lie on the rendered surface where their 3D points are
    u, v = np.rint(take.landmarks[[30, 36, 45]]).astype(int).T
    ref = scan["landmarks"][[30, 36, 45]]
    assert np.linalg.norm(take.xyz[v, u] - ref, axis=1).max() < 4.0


def test_a_mesh_takes_points_come_back_as_its_landmark_file(
    mesh_files, surface_take, landmark_take, tmp_path
):
    """The landmarks stage lifts a mesh take's points onto its render's surface: written in the
    mesh's units (here metres), the file is a landmark file the mesh reader takes back (every
    point on the mesh), and the points it projects agree with those of the true landmark file
    where the true points are the surface seen at their pixel (the points were the truth's
    projection onto the surface-only camera's image; a true point hidden behind the lips or the
    chin is not, and the lifted one is the surface in front of it). A point off the render's
    data takes the nearest surface pixel."""
    import trimesh

    from scan2morph.io import write_landmarks3d
    from scan2morph.stages import landmarks
    from scan2morph.stages.landmark_files import surface_points
    from scan2morph.stages.part import Take
    from scan2morph.store import paths

    _, (ply, txt, _) = mesh_files
    free = surface_take
    lm3 = read_landmarks3d(txt)
    cam = lm3 @ free.pose[:3, :3].T + free.pose[:3, 3]
    px = cam[:, :2] / cam[:, 2:] * np.diag(free.K)[:2] + free.K[:2, 2]
    data = {
        paths.range_image("she", "xyz"): free.xyz,
        paths.range_image("she", "color"): free.color,
        paths.clicks("she"): px,
    }
    take = Take("s1", "she", "viseme", "she", "neutral", data)
    lifted = landmarks.run(None, take, landmarks.Params()).files["xyz"]
    err = np.linalg.norm(lifted - lm3, axis=1)
    seen = err < 2.0
    print(f"\nlifted off the truth: median {np.median(err):.2f} mm, {seen.sum()} within 2 mm")
    assert np.median(err) < 0.7 and seen.sum() >= 55
    metres = tmp_path / "s_m.ply"
    mesh = trimesh.load(ply, process=False)
    mesh.apply_scale(0.001)
    mesh.export(metres)
    write_landmarks3d(tmp_path / "she.xyz", lifted / 1000.0)
    back = read_mesh_take(metres, None, tmp_path / "she.xyz", TINY_CAMERA, 1000.0)
    with_truth = landmark_take
    shift = np.linalg.norm(back.landmarks - with_truth.landmarks, axis=1)
    assert np.median(shift[seen]) < 0.5 and shift[seen].max() < 1.5
    # a point off the render's data goes to the nearest surface pixel
    off = px.copy()
    off[0] = [1.0, 1.0]
    corner = surface_points(free.xyz, off)[0]
    assert np.isfinite(corner).all()
    assert np.nanmin(np.linalg.norm(free.xyz.reshape(-1, 3) - corner, axis=1)) == 0.0


def test_a_landmark_point_cloud_saved_with_normals_or_colours_reads_as_its_points(tmp_path):
    """The .xyz corrected in MeshLab or CloudCompare comes back with normals and colours after
    each point: the points are read; a line of 2 or 4 numbers is refused."""
    points = np.random.default_rng(3).normal(0.0, 40.0, size=(68, 3))
    normals = np.tile([0.0, 0.0, 1.0], (68, 1))
    rgb = np.full((68, 3), 200.0)
    for extra in ([normals], [rgb], [normals, rgb], [rgb, np.full((68, 1), 255.0)]):
        rows = np.hstack([points, *extra])
        (tmp_path / "p.xyz").write_text("\n".join(" ".join(f"{v:.6f}" for v in r) for r in rows))
        np.testing.assert_allclose(read_landmarks3d(tmp_path / "p.xyz"), points, atol=1e-6)
    for cols in (2, 4):
        rows = np.hstack([points, np.zeros((68, 3))])[:, :cols]
        (tmp_path / "q.xyz").write_text("\n".join(" ".join(f"{v:.3f}" for v in r) for r in rows))
        with pytest.raises(InputError, match=r"q.xyz: line 1: expected 3 finite numbers \(x y z\)"):
            read_landmarks3d(tmp_path / "q.xyz")


def _landmarks_of(mesh, landmark_file, config):
    """A mesh take (as the sheet's neutral) through ingest, repair and landmarks: the stage's
    part, its ``.xyz`` points (mm) and the repaired range image (H, W, 3) mm."""
    from scan2morph.stages import ingest, landmarks, repair
    from scan2morph.stages.part import Take
    from scan2morph.store import paths

    row = dict(subject="s1", take="neutral", kind="neutral", label="neutral", modality="mesh")
    files = {"mesh": str(mesh)} | ({"landmarks": str(landmark_file)} if landmark_file else {})
    raw = ingest.run(None, Take.from_row(row, files=files), ingest.Params.from_config(config))
    attrs = raw.attrs[paths.take("neutral")]
    fixed = repair.run(
        None, Take.from_row(row, data=raw.datasets, attrs=attrs), repair.Params.from_config(config)
    )
    take = Take.from_row(row, "neutral", data=fixed.datasets, attrs=attrs)
    part = landmarks.run(None, take, landmarks.Params.from_config(config))
    return part, part.files["xyz"], fixed.datasets[paths.range_image("neutral", "xyz")]


def test_a_mesh_takes_landmark_file_given_back_comes_back_as_given(mesh_files, tmp_path):
    """The loop the docs describe: a mesh take's detected points written to its ``.xyz``, given
    back in the sheet, are written again as given, round after round (the audit's M4: the chin's
    points, lifted on the surface camera's render, lay under the chin, which the landmark
    camera's render hides; lifted again, they came back about 40 mm away, on the chin's front).
    A 51-point file's jawline is detected and lifted; its given points are written as given."""
    from tests.support.configs import repo_config

    config = repo_config() | {"mesh_camera": dict(TINY_CAMERA)}
    _, (ply, _, _) = mesh_files
    first, detected, _ = _landmarks_of(ply, None, config)
    assert first.datasets["/takes/neutral/landmark_source"] == "detected"
    write_landmarks3d(tmp_path / "round1.xyz", detected)
    given = read_landmarks3d(tmp_path / "round1.xyz")
    part, again, grid = _landmarks_of(ply, tmp_path / "round1.xyz", config)
    assert part.datasets["/takes/neutral/landmark_source"] == "clicked"
    np.testing.assert_array_equal(again, given)
    # the case is the audit's: lifted on this render, some given points move far
    from scan2morph.stages.landmark_files import surface_points

    lifted = surface_points(np.asarray(grid), part.datasets["/takes/neutral/landmarks"])
    moved = np.linalg.norm(lifted - given, axis=1)
    print(f"\nlifted again, the given points would move up to {moved.max():.1f} mm")
    assert moved.max() > 2.0  # the lift itself is within 0.6 mm of a point it sees
    # a 51-point file: its points as given, the jawline detected on the surface
    write_landmarks3d(tmp_path / "inner.xyz", given[17:])
    _, inner, _ = _landmarks_of(ply, tmp_path / "inner.xyz", config)
    np.testing.assert_array_equal(inner[17:], given[17:])
    assert np.isfinite(inner[JAW]).all()
