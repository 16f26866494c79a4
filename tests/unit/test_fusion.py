"""Several depth frames of one RGB-D take (scan2morph.scan.fusion, the reader and the sheet):
registered onto the first frame against the simulated head motion, averaged against the
noise-free depth, and every bad input named."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from scan2morph.errors import InputError
from scan2morph.io.depth_image import depth_frame_paths, read_depth_frames, write_depth_png
from scan2morph.io.rgbd import depth_points, read_rgbd_take
from scan2morph.scan.fusion import FusionParams, fuse_depth_frames
from scan2morph.sheet import read_sheet, sheet_problems
from scan2morph.stages import Take, ingest
from scan2morph.synth.rgbd import make_rgbd_take, write_rgbd_take
from tests.support.configs import SMALL_RGBD

FRAMES = 3
TAKE = ("s1", "smile", "expression", "smile1", 3)


@pytest.fixture(scope="module")
def take():
    """A smile of three depth frames with the head moving between them."""
    return make_rgbd_take(*TAKE, SMALL_RGBD | {"frames": FRAMES})


@pytest.fixture(scope="module")
def true_depth():
    """The first frame's depth without noise, flying pixels or quantisation (same pose), mm."""
    r = make_rgbd_take(
        *TAKE, SMALL_RGBD | {"noise_mm_at_1m": 0.0, "flying_fraction": 0.0, "depth_unit_mm": 0.02}
    )
    z = r["depth"].astype(float) * 0.02
    return np.where((z > 0) & (z < 1000.0), z, np.nan)  # the head, not the wall


@pytest.fixture(scope="module")
def fused(take):
    intr = take["intrinsics"]
    frames = [f.astype(float) * intr.depth_scale_mm for f in take["depth"]]
    return fuse_depth_frames(frames, intr.depth, [f"frame{k}" for k in range(FRAMES)])


def _face_point_errors(take, fused, true_depth, k):
    """(n,) distance between where the true and the found motion put frame k's face points."""
    poses = take["truth"]["frame_poses"]
    true = poses[0] @ np.linalg.inv(poses[k])
    found = fused.transforms[k]
    ref = depth_points(np.nan_to_num(true_depth), take["intrinsics"].depth)
    ref = ref[np.isfinite(ref).all(axis=2)]
    p = (ref - true[:3, 3]) @ true[:3, :3]  # frame k's points of the face
    moved = p @ found[:3, :3].T + found[:3, 3]
    return np.linalg.norm(moved - ref, axis=1), np.linalg.norm(p - ref, axis=1)


def test_each_frame_is_registered_onto_the_first(take, fused, true_depth):
    """Against the simulated head motion: the face lands within a fraction of a mm (it moved
    0.5-2 mm between frames; measured 0.17-0.23 mm median)."""
    assert len(take["truth"]["frame_poses"]) == FRAMES
    np.testing.assert_array_equal(fused.transforms[0], np.eye(4))
    for k in range(1, FRAMES):
        err, moved = _face_point_errors(take, fused, true_depth, k)
        assert np.median(moved) > 0.5, k  # there was motion to undo
        assert np.median(err) < 0.35, (k, np.median(err))
        assert np.percentile(err, 95) < 0.6, k
    assert (fused.fitness[1:] > 0.9).all()
    assert (fused.rmse_mm[1:] < 1.5).all()


def test_fused_depth_is_closer_to_the_truth_than_one_frame(take, fused, true_depth):
    """Median depth error of the face: fused < 0.6 x the first frame's (measured 0.27 against
    0.64 mm), with most of the face kept."""
    single = take["depth"][0].astype(float) * take["intrinsics"].depth_scale_mm
    face = np.isfinite(true_depth)
    errors = {}
    for name, z in (("single", np.where(single > 0, single, np.nan)), ("fused", fused.depth_mm)):
        e = np.abs(z - true_depth)[face]
        errors[name] = (np.median(e[np.isfinite(e)]), np.isfinite(e).mean())
    print(errors)
    assert errors["fused"][0] < 0.6 * errors["single"][0]
    assert errors["fused"][1] > 0.85


def test_identical_frames_fuse_to_themselves(take):
    intr = take["intrinsics"]
    z = take["depth"][0].astype(float) * intr.depth_scale_mm
    out = fuse_depth_frames([z, z.copy()], intr.depth, ["a", "b"])
    np.testing.assert_allclose(out.transforms[1], np.eye(4), atol=1e-6)
    seen = z > 0
    kept = np.isfinite(out.depth_mm)
    assert not (kept & ~seen).any()
    np.testing.assert_allclose(out.depth_mm[kept], z[kept], atol=1e-6)
    # all but the odd pixel at a depth step, where the frame's surface is not meshed
    assert kept[seen].mean() > 0.99 and (out.count[kept] >= 1).all()


def test_a_frame_of_another_pose_is_refused_naming_it(take):
    """A frame of the head 60 mm to the side is not a frame of this take."""
    intr = take["intrinsics"]
    z = take["depth"][0].astype(float) * intr.depth_scale_mm
    shifted = np.zeros_like(z)
    shifted[:, 40:] = z[:, :-40]  # ~80 mm at 600 mm with a 300 px focal length
    with pytest.raises(InputError, match=r"other_take_depth\.png.*does not register"):
        fuse_depth_frames([z, shifted], intr.depth, ["first.png", "other_take_depth.png"])
    # a frame 5 mm farther away, against a 2 mm limit
    farther = np.where(z > 0, z + 5.0, 0.0)
    with pytest.raises(
        InputError, match=r"b\.png.*does not register.*motion 0\.\d degrees, [45]\.\d mm"
    ):
        fuse_depth_frames(
            [z, farther], intr.depth, ["a.png", "b.png"], FusionParams(max_motion_mm=2.0)
        )


def _write(take, folder, names):
    folder.mkdir(parents=True, exist_ok=True)
    depth = [folder / n for n in names]
    files = {
        "color": folder.parent / "color.png",
        "intrinsics": folder.parent / "intrinsics.yaml",
        "landmarks": folder.parent / "take.pts",
        "truth": folder.parent / "truth.npz",
    }
    write_rgbd_take(take, depth, *files.values())
    return depth, files


def test_a_folder_or_a_list_of_frames_reads_as_one_fused_take(take, tmp_path):
    """The reader fuses a folder's frames (name order) or a ';' list alike, and the fused
    take lies closer to the true surface than its first frame alone."""
    depth, files = _write(take, tmp_path / "frames", ["f1.png", "f2.png", "f3.png"])
    assert depth_frame_paths(tmp_path / "frames") == depth
    assert depth_frame_paths(" ; ".join(map(str, depth))) == depth

    def fuse(frames, camera, sources):
        return fuse_depth_frames(frames, camera, sources)

    args = (files["color"], files["intrinsics"], files["landmarks"])
    by_folder = read_rgbd_take(str(tmp_path / "frames"), *args, fuse)
    by_list = read_rgbd_take(";".join(map(str, depth)), *args, fuse)
    single = read_rgbd_take(depth[0], *args)
    np.testing.assert_array_equal(by_folder.xyz, by_list.xyz)
    assert by_folder.fusion is not None and single.fusion is None
    truth = take["truth"]["xyz_true"]
    face = np.isfinite(truth).all(axis=2) & (truth[..., 2] < 1000.0)
    errors = {}
    for name, scan in (("single", single), ("fused", by_folder)):
        e = np.linalg.norm(scan.xyz - truth, axis=2)[face]
        errors[name] = np.median(e[np.isfinite(e)])
    assert errors["fused"] < 0.7 * errors["single"], errors
    with pytest.raises(ValueError, match="fuse"):
        read_rgbd_take(str(tmp_path / "frames"), *args)


def test_ingest_records_the_frames(take, tmp_path):
    depth, files = _write(take, tmp_path / "frames", ["a.png", "b.png", "c.png"])
    row = {"subject": "s1", "take": "smile1", "kind": "expression", "label": "smile"}
    row |= {"modality": "rgbd", "units": ""}
    inputs = {
        "depth": ";".join(map(str, depth)),
        "color": str(files["color"]),
        "intrinsics": str(files["intrinsics"]),
    }
    part = ingest.run(None, Take.from_row(row, files=inputs), ingest.Params.from_config({}))
    attrs = part.attrs["/takes/smile1"]
    assert attrs["depth_frames"] == 3
    assert len(attrs["depth_frame_motion_deg"]) == 3 and attrs["depth_frame_motion_deg"][0] == 0
    assert len(attrs["input_sha256_depth"].split(";")) == 3


# --------------------------------------------------------------------------------------------
# bad input


def test_an_empty_folder_is_named(tmp_path):
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "notes.txt").write_text("not a frame")
    with pytest.raises(InputError, match=r"frames.*holds no depth frames"):
        depth_frame_paths(tmp_path / "frames")


def test_frames_of_different_sizes_are_named(tmp_path):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    write_depth_png(a, np.full((24, 32), 600, np.uint16))
    write_depth_png(b, np.full((24, 30), 600, np.uint16))
    with pytest.raises(InputError, match=r"b\.png.*30x24 px but the take's first frame a\.png"):
        read_depth_frames(f"{a};{b}")


def test_a_missing_frame_is_named(tmp_path):
    a = tmp_path / "a.png"
    write_depth_png(a, np.full((24, 32), 600, np.uint16))
    with pytest.raises(InputError, match=r"missing\.png.*file not found"):
        read_depth_frames([a, tmp_path / "missing.png"])


def test_the_sheet_resolves_each_frame_and_names_a_missing_one(tmp_path):
    (tmp_path / "scans").mkdir()
    for name in ("n_depth.png", "n.png", "n.yaml", "n_depth2.png", "c_depth.png", "c.png"):
        (tmp_path / "scans" / name).write_bytes(b"")
    sheet = tmp_path / "sheet.tsv"
    rows = [
        ["s1", "neutral", "neutral", "neutral", "rgbd", "scans/n_depth.png; scans/n_depth2.png"],
        ["s1", "car", "viseme", "car", "rgbd", "scans/c_depth.png;scans/gone.png"],
    ]
    table = pd.DataFrame(rows, columns=["subject", "take", "kind", "label", "modality", "depth"])
    table["color"], table["intrinsics"] = ["scans/n.png", "scans/c.png"], "scans/n.yaml"
    table.to_csv(sheet, sep="\t", index=False)
    df = read_sheet(sheet)
    first = df["depth"].iloc[0].split(";")
    assert [p.strip() for p in first] == [
        str(tmp_path / "scans" / "n_depth.png"),
        str(tmp_path / "scans" / "n_depth2.png"),
    ]
    problems = sheet_problems(df)["s1"]
    assert len(problems) == 1
    take, problem = problems[0]
    assert take == "car" and "column 'depth': file not found" in problem
    assert problem.endswith(str(tmp_path / "scans" / "gone.png"))
