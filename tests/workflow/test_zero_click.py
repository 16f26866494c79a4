"""Scans without clicks, end to end: a user's sheet that mixes detected, clicked and 51-point
takes, and a take with no face in it, through the whole workflow.

The takes are our synthetic generator's (320 x 240, so that the test has the truth), written as a
user brings them; the sheet gives a landmark file to one take only and a 51-point file to
another. The take without a face (a flat board) is left out with one line; the subject is
built from the rest.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from scan2morph.evaluate.landmarks import landmark_errors
from scan2morph.io import read_pts, write_abs, write_color, write_pts
from scan2morph.store import open_store, paths
from scan2morph.synth.cohort import make_take
from tests.support.workflow_api import run_workflow

pytestmark = pytest.mark.slow

SCANNER = dict(width=320, height=240, focal_px=725.0)
TAKES = [
    ("neutral", "neutral", "neutral", "detect"),
    ("car", "viseme", "car", "clicked"),
    ("too", "viseme", "too", "inner51"),
    ("smile1", "expression", "smile", "detect"),
]
SUBJECT = "zc"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    work = tmp_path_factory.mktemp("zero_click")
    data = work / "scans"
    data.mkdir()
    rows, truths = [], {}
    for take, kind, label, how in TAKES:
        r = make_take("zc", label, kind, take, 7, SCANNER)
        write_abs(data / f"{take}.abs.gz", r["xyz"])
        write_color(data / f"{take}.png", r["color"])
        truths[take] = r["truth"]["landmarks2d"]
        pts = ""
        if how == "clicked":
            write_pts(data / f"{take}.pts", r["landmarks"])
            pts = f"scans/{take}.pts"
        elif how == "inner51":
            write_pts(data / f"{take}.pts", r["landmarks"][17:])
            pts = f"scans/{take}.pts"
        rows.append(
            [SUBJECT, take, kind, label, "range", f"scans/{take}.abs.gz", f"scans/{take}.png", pts]
        )
    # a flat board in front of the scanner: no face on it
    board = make_take("zc", "neutral", "neutral", "neutral", 7, SCANNER)
    flat = board["xyz"].copy()
    ok = np.isfinite(flat).all(axis=-1)
    flat[ok, 2] = np.nanmedian(flat[..., 2])
    write_abs(data / "board.abs.gz", flat)
    write_color(data / "board.png", board["color"])
    rows.append(
        [
            SUBJECT,
            "board",
            "expression",
            "sad",
            "range",
            "scans/board.abs.gz",
            "scans/board.png",
            "",
        ]
    )
    # a subject whose neutral has no face: it stops alone
    for take, kind, label, scan in (
        ("neutral", "neutral", "neutral", "board"),
        ("car", "viseme", "car", "car"),
    ):
        rows.append(
            ["flat", take, kind, label, "range", f"scans/{scan}.abs.gz", f"scans/{scan}.png", ""]
        )
    header = ["subject", "take", "kind", "label", "modality", "xyz", "color", "landmarks"]
    (work / "subjects.tsv").write_text("\n".join("\t".join(r) for r in [header, *rows]) + "\n")
    cfg = dict(
        subjects=str(work / "subjects.tsv"),
        synthetic=dict(subjects=0),
        modal=dict(modes=10, reconstruction_k=[1, 2, 5, 10]),
    )
    (work / "cfg.yaml").write_text(yaml.safe_dump(cfg))
    targets = [f"results/{s}/report.html" for s in (SUBJECT, "flat")]
    ok = run_workflow(work, work / "cfg.yaml", targets=targets)
    assert not ok  # the subject "flat" stops: its neutral has no face
    assert (work / "results" / SUBJECT / "report.html").is_file(), f"see {work / 'logs'}"
    return work, truths


def test_each_take_says_where_its_landmarks_come_from(run):
    work, _ = run
    with open_store(work / "results" / SUBJECT / f"{SUBJECT}.h5") as h5:
        sources = {
            t: h5[paths.landmark_info(t, "source")].asstr()[()]
            for t in ("neutral", "car", "too", "smile1")
        }
        detector = h5[paths.landmark_info("neutral", "detector")].asstr()[()]
        assert paths.landmark_confidence("neutral") in h5
        assert paths.landmark_confidence("car") not in h5
        assert h5[paths.landmark_info("car", "detector")].asstr()[()] == ""
    assert sources == {
        "neutral": "detected",
        "car": "clicked",
        "too": "clicked+detected jawline",
        "smile1": "detected",
    }
    assert detector.startswith("scan2morph-cascade")


def test_detected_landmarks_lie_near_the_truth_and_come_back_as_pts(run):
    work, truths = run
    for take, how in (("neutral", "detect"), ("smile1", "detect"), ("too", "inner51")):
        pts = read_pts(work / "results" / SUBJECT / "landmarks" / f"{take}.pts")
        errors = landmark_errors(pts, truths[take])
        print(f"\n{take} ({how}): {errors}")
        assert errors["inner_median_px"] < 2.0, take  # 320 x 240: half the 640 x 480 pixel
    # a clicked take's file is its clicks
    clicked = read_pts(work / "scans" / "car.pts")
    np.testing.assert_allclose(
        read_pts(work / "results" / SUBJECT / "landmarks" / "car.pts"), clicked, atol=1e-3
    )


def test_a_take_without_a_face_is_left_out_with_one_line(run):
    work, _ = run
    with open_store(work / "results" / SUBJECT / f"{SUBJECT}.h5") as h5:
        assert "board" in h5[paths.FAILED]
        stage = h5[paths.failed("board", "stage")].asstr()[()]
        reason = h5[paths.failed("board", "reason")].asstr()[()]
        assert "board" not in h5[paths.TAKES]
        assert {"car", "too", "smile1"} <= set(h5[paths.VISEMES]) | set(h5[paths.EXPRESSIONS])
    assert stage == "landmarks"
    assert "face" in reason and "\n" not in reason
    report = (work / "results" / SUBJECT / "report.html").read_text()
    assert "board" in report and "left out" in report


def test_a_neutral_without_a_face_stops_only_its_subject(run):
    work, _ = run
    assert not (work / "results" / "flat" / "flat.h5").exists()
    logs = "\n".join(p.read_text() for p in (work / "logs").rglob("*.log") if "flat" in str(p))
    assert "the neutral take neutral was refused at landmarks" in logs
    assert "subject is not built" in logs
