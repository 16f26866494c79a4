"""A user's RGB-D take whose ``depth`` names a folder of frames, through the workflow.

docs/inputs.md: a take's depth may be one file, files separated by ``;`` or a folder (its depth
files in name order). A folder reached the subject's check job as it was named, and checksumming
it (a folder is not a file) stopped the subject with a traceback. The workflow now lists the
folder's frames as the take's inputs: each is tracked, so a frame replaced inside the folder re-runs
the take, also when its time is older than the results (as ``rsync -a``, ``cp -p`` or an archive
leave it). A folder without frames leaves its take out with one line.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import h5py
import pytest
import yaml

from scan2morph.synth.rgbd import make_rgbd_take, write_rgbd_take
from tests.support.configs import SMALL_RGBD
from tests.support.workflow_api import REPO, run_workflow

pytestmark = pytest.mark.slow

HEADER = "subject\ttake\tkind\tlabel\tmodality\tdepth\tcolor\tintrinsics\tlandmarks\n"
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
        own = [f"{subject}/{take}/{n}" for n in ("color.png", "intrinsics.yaml", "take.pts")]
        rows.append("\t".join([subject, take, kind, take, "rgbd", cell, *own]) + "\n")
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
    (scans / "subjects.tsv").write_text(HEADER + "".join(rows))
    configfile = work / "frames.yaml"
    configfile.write_text(
        yaml.safe_dump({"subjects": str(scans / "subjects.tsv"), "synthetic": {"subjects": 0}})
    )
    targets = [f"results/{s}/{s}.h5" for s in ("bob", "eve")]
    ok = run_workflow(work, configfile, targets=targets)
    return work, configfile, targets, ok


def test_a_folder_of_frames_is_fused_and_each_frame_checksummed(run):
    work, _, _, ok = run
    assert ok
    with h5py.File(work / "results" / "bob" / "takes" / "car" / "ingest.h5") as h5:
        attrs = h5["takes/car"].attrs
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
