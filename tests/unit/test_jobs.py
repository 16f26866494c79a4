"""A job's logging (everything in its log file, only problems on the console, one line each) and its memory request."""

from __future__ import annotations

import subprocess
import sys

JOB = """
import logging, sys
from scan2morph.errors import InputError
from scan2morph.jobs import run_job

def job():
    for _ in range(300):
        logging.getLogger("OpenGL.platform").info("Platform import failed (likely during shutdown)")
    logging.getLogger("scan2morph").info("car: 1682 vertices")
    logging.getLogger("scan2morph").warning("car: alignment failed its quality gate")
    if sys.argv[2] == "bad":
        raise InputError("alice/car.pts", "n_points: expected 68 (iBUG-68), got 67")
    if sys.argv[2] == "full":
        import errno
        raise OSError(errno.ENOSPC, "No space left on device", "results/alice/alice.h5")

run_job(sys.argv[1], job)
"""


def _run(tmp_path, mode):
    log = tmp_path / "job.log"
    res = subprocess.run(
        [sys.executable, "-c", JOB, str(log), mode], capture_output=True, text=True, timeout=120
    )
    return res, log.read_text()


def test_console_gets_problems_only_and_the_log_everything(tmp_path):
    res, log = _run(tmp_path, "good")
    assert res.returncode == 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].endswith("WARNING car: alignment failed its quality gate")
    assert log.count("Platform import failed") == 300
    assert "INFO car: 1682 vertices" in log


def test_bad_input_is_one_line_and_exit_status_1(tmp_path):
    res, log = _run(tmp_path, "bad")
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 2  # the warning, then the bad input: no traceback
    assert lines[1].endswith(
        "ERROR bad input: alice/car.pts: n_points: expected 68 (iBUG-68), got 67"
    )
    assert "Traceback" not in res.stderr and "bad input" in log


def test_a_logs_last_error_is_found_in_this_runs_logs_only(tmp_path):
    """The run's last console lines name why a subject's job stopped: the last error a job
    wrote (``bad input: `` left off), from the first of its logs written in this run that has
    one; a log written before the run, or without an error, says nothing."""
    import os

    from scan2morph.jobs import job_error

    res, _ = _run(tmp_path, "bad")
    assert res.returncode == 1
    log, quiet = tmp_path / "job.log", tmp_path / "quiet.log"
    quiet.write_text("2026-12-06 15:19:26,823 WARNING car: alignment failed its quality gate\n")
    since = log.stat().st_mtime
    assert job_error([quiet, tmp_path / "none.log", log], since) == (
        "alice/car.pts: n_points: expected 68 (iBUG-68), got 67",
        log,
    )
    os.utime(log, (since - 60, since - 60))  # an earlier run's
    assert job_error([quiet, log], since) is None


def test_a_full_disk_is_one_line(tmp_path):
    res, log = _run(tmp_path, "full")
    assert res.returncode == 1
    assert (
        res.stderr.strip()
        .splitlines()[-1]
        .endswith("ERROR no space left on device writing results/alice/alice.h5")
    )
    assert "Traceback" not in res.stderr


def test_a_job_profiles_itself_when_asked(tmp_path, monkeypatch):
    """With SCAN2MORPH_PROFILE set, a job writes its cProfile statistics (the body's functions,
    not the wrapper's), the CPU time spent before its body and the body's wall and CPU time
    (benchmarks/bench_profile.py, bench_subject_jobs.py)."""
    import json
    import pstats
    import time

    from scan2morph.jobs import PROFILE_ENV, run_job

    def busy_body():
        t0 = time.process_time()
        while time.process_time() - t0 < 0.05:
            pass

    monkeypatch.setattr("scan2morph.jobs._STARTED", False)  # a fresh process
    monkeypatch.setenv(PROFILE_ENV, str(tmp_path / "prof"))
    run_job(tmp_path / "logs" / "align" / "s1" / "car.log", busy_body)
    stats = pstats.Stats(str(tmp_path / "prof" / "align-s1-car.prof"))
    own = {key[2]: value[3] for key, value in stats.stats.items()}
    assert own["busy_body"] >= 0.05
    record = json.loads((tmp_path / "prof" / "align-s1-car.json").read_text())
    assert record["startup_cpu_s"] > 0 and record["body_wall_s"] >= 0.05
    # the body's own CPU: the busy loop's 0.05 s, not the start-up's
    assert 0.05 <= record["body_cpu_s"] < record["body_wall_s"] + 0.01
    # a second job of the same process (a take's next stage): no start-up, its own body's CPU
    run_job(tmp_path / "logs" / "refine" / "s1" / "car.log", busy_body)
    record = json.loads((tmp_path / "prof" / "refine-s1-car.json").read_text())
    assert record["startup_cpu_s"] == 0.0
    assert 0.05 <= record["body_cpu_s"] < 0.09  # not the first job's too
    monkeypatch.delenv(PROFILE_ENV)
    run_job(tmp_path / "logs" / "align" / "s1" / "too.log", busy_body)
    assert not (tmp_path / "prof" / "align-s1-too.prof").exists()


def test_a_job_runs_opencv_on_its_own_threads_for_the_same_flow(tmp_path, monkeypatch):
    """Snakemake gives a job OMP_NUM_THREADS = its threads; the job runs OpenCV's pool on as
    many (not on every core), and the refinement's optical flow is the same, bit for bit;
    OpenCV's setting comes back afterwards. Outside a job (no OMP_NUM_THREADS) nothing is set."""
    import cv2
    import numpy as np
    from scipy.ndimage import gaussian_filter

    from scan2morph.jobs import job_threads, run_job
    from scan2morph.refine.flow import measure_flow

    noise = gaussian_filter(np.random.default_rng(2).standard_normal((200, 240)), 1.5)
    reference = 150.0 + 25.0 * noise / noise.std()
    moving = np.roll(reference, 2, axis=1) + np.roll(reference, 1, axis=0) * 0.1
    before = cv2.getNumThreads()
    plain = measure_flow(reference, moving)
    seen = {}

    def body():
        seen["threads"] = cv2.getNumThreads()
        seen["env"] = __import__("os").environ.get("OPENCV_FOR_THREADS_NUM")
        seen["flow"] = measure_flow(reference, moving)

    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    monkeypatch.delenv("OPENCV_FOR_THREADS_NUM", raising=False)
    run_job(tmp_path / "job.log", body)
    assert seen["threads"] == 1 and seen["env"] == "1"
    assert cv2.getNumThreads() == before
    for got, want in zip(seen["flow"][:2], plain[:2], strict=True):
        np.testing.assert_array_equal(got, want)
    assert (plain[1] > 0).mean() > 0.5  # the flow measured something
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert job_threads() is None


def test_a_jobs_memory_grows_with_its_largest_mesh_scan(tmp_path):
    """The request is the base plus 50 MB per MB of the largest PLY or GLB (10 of an OBJ or
    glTF) among the job's inputs, nested lists included; other files, and a file the run has not
    made yet, add nothing."""
    from scan2morph.jobs import memory_mb

    mb = 2**20
    (tmp_path / "dense.ply").write_bytes(b"\0" * (4 * mb))
    (tmp_path / "text.OBJ").write_bytes(b"\0" * (10 * mb))
    (tmp_path / "big.abs").write_bytes(b"\0" * (30 * mb))
    files = [str(tmp_path / "big.abs"), [str(tmp_path / "text.OBJ"), str(tmp_path / "dense.ply")]]
    assert memory_mb(files, 900) == 900 + 200  # the PLY: 4 x 50 > 10 x 10
    assert memory_mb([str(tmp_path / "text.OBJ")], 500) == 500 + 100
    assert memory_mb([str(tmp_path / "big.abs"), str(tmp_path / "later.glb")], 900) == 900
    assert memory_mb([], 500) == 500
