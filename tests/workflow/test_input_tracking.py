"""A user's inputs as the workflow tracks them: an RGB-D take whose ``depth`` names a folder of
frames, a textured OBJ mesh take (its MTL and texture beside it), files replaced by ones dated
older than the results.

docs/inputs.md: a take's depth may be one file, files separated by ``;`` or a folder (its depth
files in name order). A folder reached the subject's check job as it was named, and checksumming
it (a folder is not a file) stopped the subject with a traceback. The workflow now lists the
folder's frames as the take's inputs: each is tracked, so a frame replaced inside the folder re-runs
the take, also when its time is older than the results (as ``rsync -a``, ``cp -p`` or an archive
leave it). A folder without frames leaves its take out with one line. An OBJ's MTL and texture
were neither inputs of its take's job nor in its stages' fingerprints: a texture retouched (the
OBJ the same, or written again unchanged) kept the old results.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import h5py
import numpy as np
import pytest
import trimesh
import yaml
from PIL import Image
from scipy.spatial import cKDTree

from scan2morph.store import paths
from scan2morph.synth.mesh_scan import make_mesh_take, write_landmarks3d
from scan2morph.synth.rgbd import make_rgbd_take, write_rgbd_take
from tests.support.configs import SMALL_RGBD
from tests.support.workflow_api import REPO, run_workflow

pytestmark = pytest.mark.slow

HEADER = "subject\ttake\tkind\tlabel\tmodality\tdepth\tcolor\tintrinsics\tmesh\tlandmarks\n"
#: take, kind, frames (1: one file, else a folder of that many)
TAKES = [("neutral", "neutral", 1), ("car", "viseme", 2)]


def _write_subject(scans, subject, empty_folder=False):
    rows = []
    for take, kind, frames in TAKES:
        result = make_rgbd_take(subject, take, kind, take, 5, SMALL_RGBD | {"frames": frames})
        folder = scans / subject / take
        (folder / "depth").mkdir(parents=True)
        depth = [folder / "depth" / f"f{k}.png" for k in range(frames)]
        files = [folder / n for n in ("color.png", "intrinsics.yaml", "take.pts", "truth.npz")]
        write_rgbd_take(result, depth if frames > 1 else depth[0], *files)
        cell = f"{subject}/{take}/depth" if frames > 1 else f"{subject}/{take}/depth/f0.png"
        if frames > 1 and empty_folder:
            for f in depth:
                f.unlink()
            (folder / "depth" / "notes.txt").write_text("the frames were not copied\n")
        own = [f"{subject}/{take}/{n}" for n in ("color.png", "intrinsics.yaml", "", "take.pts")]
        rows.append("\t".join([subject, take, kind, take, "rgbd", cell, *own]) + "\n")
    return rows


def _write_mesh_subject(scans, subject):
    """A neutral and a viseme as OBJ + MTL + PNG, the vertex colours baked into the texture
    through a cylindrical UV map, and their 3D landmarks."""
    rows = []
    for take, kind, _ in TAKES:
        scan = make_mesh_take(subject, take, kind, take, seed=3)
        folder = scans / subject / take
        folder.mkdir(parents=True)
        v = scan["vertices"]
        centre = v.mean(axis=0)
        u = np.arctan2(v[:, 0] - centre[0], v[:, 2] - centre[2]) / (2 * np.pi) + 0.5
        uv = np.column_stack([u, (v[:, 1] - v[:, 1].min()) / np.ptp(v[:, 1])])
        texel = (np.arange(256) + 0.5) / 256
        tu, tv = np.meshgrid(texel, 1.0 - texel)  # image rows run down: row 0 at v = 1
        _, nearest = cKDTree(uv).query(np.column_stack([tu.ravel(), tv.ravel()]))
        image = Image.fromarray(scan["colors"][nearest].reshape(256, 256, 3))
        visual = trimesh.visual.TextureVisuals(uv=uv, image=image)
        trimesh.Trimesh(v, scan["faces"], visual=visual, process=False).export(folder / "scan.obj")
        write_landmarks3d(folder / "scan.txt", scan["landmarks"])
        cells = ["", "", "", f"{subject}/{take}/scan.obj", f"{subject}/{take}/scan.txt"]
        rows.append("\t".join([subject, take, kind, take, "mesh", *cells]) + "\n")
    return rows


def _snakemake(work, configfile, *args):
    """Snakemake's command line with ``args`` (targets first)."""
    cmd = [str(Path(sys.executable).with_name("snakemake")), *args, "--cores", "1"]
    cmd += ["-s", str(REPO / "Snakefile"), "-d", str(work)]
    cmd += ["--configfile", str(REPO / "config" / "config.yaml"), str(configfile)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    work = tmp_path_factory.mktemp("frames")
    scans = work / "scans"
    rows = _write_subject(scans, "bob") + _write_subject(scans, "eve", empty_folder=True)
    rows += _write_mesh_subject(scans, "max")
    (scans / "subjects.tsv").write_text(HEADER + "".join(rows))
    configfile = work / "frames.yaml"
    configfile.write_text(
        yaml.safe_dump({"subjects": str(scans / "subjects.tsv"), "synthetic": {"subjects": 0}})
    )
    targets = [f"results/{s}/{s}.h5" for s in ("bob", "eve", "max")]
    ok = run_workflow(work, configfile, targets=targets)
    return work, configfile, targets, ok


def test_a_folder_of_frames_is_fused_and_each_frame_checksummed(run):
    work, _, _, ok = run
    assert ok
    with h5py.File(work / "results" / "bob" / "takes" / "car" / "ingest.h5") as h5:
        attrs = h5[paths.take("car")].attrs
        assert int(attrs["depth_frames"]) == 2
        assert len(str(attrs["input_sha256_depth"]).split(";")) == 2


def test_a_folder_without_frames_leaves_its_take_out_in_one_line(run):
    work, _, _, _ = run
    log = (work / "logs" / "check_subject" / "eve.log").read_text()
    assert "Traceback" not in log, log
    assert "eve/car" in log and "the folder holds no depth frames" in log, log
    assert (work / "results" / "eve" / "eve.h5").is_file()  # the neutral's subject goes on


def test_a_frame_replaced_with_an_older_time_reruns_its_take(run):
    """The frame's new content with a time older than every result: Snakemake's own rule sees
    nothing newer; the files' sizes and times (a param of the take job) do."""
    work, configfile, targets, _ = run
    frame = work / "scans" / "bob" / "car" / "depth" / "f1.png"
    depth = cv2.imread(str(frame), cv2.IMREAD_UNCHANGED)
    depth[120, 160] += 3
    cv2.imwrite(str(frame), depth)
    os.utime(frame, ns=(10**18, 10**18))  # 2001: older than the results
    plan = _snakemake(work, configfile, *targets, "-n", "--quiet", "rules")
    assert plan.returncode == 0, plan.stderr
    rules = [line.split()[0] for line in plan.stdout.splitlines() if line.strip()]
    assert "take" in rules, plan.stdout
    parts = {t: work / "results" / "bob" / "takes" / t / "ingest.h5" for t in ("neutral", "car")}
    before = {t: p.stat().st_mtime_ns for t, p in parts.items()}
    assert run_workflow(work, configfile, targets=targets)
    car = (work / "logs" / "take" / "bob" / "car.log").read_text().splitlines()
    assert car[0] == "ingest: run", car
    assert parts["car"].stat().st_mtime_ns != before["car"]
    assert parts["neutral"].stat().st_mtime_ns == before["neutral"]  # its job did not run


def test_a_texture_retouched_beside_its_obj_reruns_its_take(run):
    """The texture changed, the OBJ written again unchanged (newer, same bytes): the take's
    ingest reads the new texture. Its MTL and texture are the job's inputs, and in the
    fingerprint of its stages with the OBJ's checksum."""
    work, configfile, targets, _ = run
    folder = work / "scans" / "max" / "car"
    (texture,) = folder.glob("*.png")
    part = work / "results" / "max" / "takes" / "car" / "ingest.h5"
    with h5py.File(part) as h5:
        before = np.asarray(h5[paths.raw("car", "color")])
    image = np.asarray(Image.open(texture)).copy()
    image[..., 2] = 255 - image[..., 2]
    Image.fromarray(image).save(texture)
    plan = _snakemake(work, configfile, *targets, "-n", "--quiet", "rules")
    assert "take" in plan.stdout, plan.stdout
    obj = folder / "scan.obj"
    obj.write_bytes(obj.read_bytes())  # written again: newer, the same bytes
    assert run_workflow(work, configfile, targets=targets)
    log = (work / "logs" / "take" / "max" / "car.log").read_text().splitlines()
    assert log[0] == "ingest: run", log
    with h5py.File(part) as h5:
        after = np.asarray(h5[paths.raw("car", "color")])
    face = (before > 0).any(axis=2)
    assert np.abs(after[face].astype(int) - before[face].astype(int))[:, 2].mean() > 50
