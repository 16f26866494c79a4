"""Take isolation, the per-subject check of every file at once, handedness and a full disk.

A take that fails a per-take stage is left out of its subject with its reason (the failure
record); its later stages hand the record on; a failed neutral stops the subject; the store keeps
the record and none of the take's data. The end-to-end case (a subject with one broken take of
each kind) is in ``tests/workflow/test_workflow.py``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from scan2morph.errors import InputError, OutputError
from scan2morph.io import check_handedness, write_abs, write_color
from scan2morph.io.check import take_file_problems
from scan2morph.stages import Subject, Take, check
from scan2morph.stages.failure import Failure, failures, part_failures, run_take_job, usable
from scan2morph.store import merge_parts, paths, read_part, write_part
from scan2morph.synth import make_take, write_take
from tests.support.configs import load_yaml

TINY = dict(width=160, height=120, focal_px=362.5, distance_mm=1000.0)
SUBJECT = Subject("s", {"n": "neutral", "car": "viseme", "smile": "expression"}, {})


@pytest.fixture(scope="module")
def take():
    return make_take("s1", "car", "viseme", "car", seed=3, params=dict(TINY))


def _run(job, tmp_path, inputs=(), take="car", stage="fit"):
    part = tmp_path / f"{stage}.h5"
    run_take_job(tmp_path / "log.txt", job, take=take, stage=stage, inputs=inputs, part=part)
    return part


def test_a_take_refused_by_its_stage_gets_a_failure_record_not_a_failed_job(tmp_path):
    def job():
        raise InputError("s/car", "landmarks: the template folds (12 triangles)")

    part = _run(job, tmp_path)  # returns: the job did not fail
    assert failures(read_part(part)) == {
        "car": Failure("car", "fit", "s/car: landmarks: the template folds (12 triangles)")
    }
    assert "car is left out of its subject" in (tmp_path / "log.txt").read_text()


def test_later_stages_hand_the_record_on_without_running(tmp_path):
    first = _run(
        lambda: (_ for _ in ()).throw(InputError("a.pts", "bad")), tmp_path, stage="ingest"
    )
    ran = []
    second = _run(lambda: ran.append(1), tmp_path, inputs=[first], stage="repair")
    assert ran == []
    assert part_failures([second]) == {"car": Failure("car", "ingest", "a.pts: bad")}
    # a good input runs the job
    good = tmp_path / "good.h5"
    write_part(good, {paths.landmarks("car"): np.zeros((68, 2))})
    _run(lambda: ran.append(1), tmp_path, inputs=[good], stage="align")
    assert ran == [1]


def test_a_full_disk_or_a_bug_still_fails_the_job(tmp_path):
    with pytest.raises(SystemExit):
        _run(lambda: (_ for _ in ()).throw(OutputError(tmp_path / "x.h5")), tmp_path)
    assert not (tmp_path / "fit.h5").exists()
    with pytest.raises(ZeroDivisionError):
        _run(lambda: 1 / 0, tmp_path)
    assert not (tmp_path / "fit.h5").exists()


def test_the_subject_drops_failed_takes_and_stops_on_a_failed_neutral():
    data = Failure("car", "align", "why").datasets()
    kept = usable(SUBJECT, data)
    assert kept.visemes == [] and kept.expressions == ["smile"] and kept.neutral == "n"
    assert usable(SUBJECT, {}) == SUBJECT
    with pytest.raises(InputError, match=r"^s: the neutral take n was refused at ingest \(x.pts: "):
        usable(SUBJECT, Failure("n", "ingest", "x.pts: 67 points").datasets())


def test_the_store_keeps_the_record_once_and_none_of_the_takes_data(tmp_path):
    record = Failure("car", "fit", "why").datasets()
    ingest = tmp_path / "ingest.h5"
    write_part(ingest, {paths.landmarks("car"): np.zeros((68, 2))})
    parts = [ingest]
    for stage in ("fit", "align", "refine"):  # every later part repeats the record
        write_part(tmp_path / f"{stage}.h5", record)
        parts.append(tmp_path / f"{stage}.h5")
    write_part(tmp_path / "neutral.h5", {paths.landmarks("n"): np.ones((68, 2))})
    store = tmp_path / "s.h5"
    merge_parts(store, [*parts, tmp_path / "neutral.h5"], "s", "0" * 64, exclude=["/takes/car"])
    with h5py.File(store) as h5:
        assert list(h5[paths.TAKES]) == ["n"]
        assert failures(h5) == {"car": Failure("car", "fit", "why")}
    # two parts writing one dataset is still an error, and so is a record that differs
    write_part(tmp_path / "other.h5", Failure("car", "align", "else").datasets())
    with pytest.raises(InputError, match="already in the store"):
        merge_parts(store, [parts[1], tmp_path / "other.h5"], "s", "0" * 64)


def test_check_finds_every_problem_of_every_take_at_once(tmp_path, take):
    d = tmp_path
    for name in ("n", "car", "too"):
        write_take(take, d / f"{name}.abs.gz", d / f"{name}.png", d / f"{name}.pts", d / "t.npz")
    lines = (d / "car.pts").read_text().splitlines()
    (d / "car.pts").write_text("\n".join([lines[0], "n_points: 67", "{", *lines[3:-2], "}"]))
    write_color(d / "car.png", take["color"][:-10])
    xyz = take["xyz"]

    write_abs(d / "too.abs.gz", xyz[..., [1, 0, 2]])  # mirrored: found by the cross-check
    files = {
        t: {"xyz": d / f"{t}.abs.gz", "color": d / f"{t}.png", "landmarks": d / f"{t}.pts"}
        for t in ("n", "car", "too")
    }
    assert take_file_problems("range", files["n"]) == []
    car = take_file_problems("range", files["car"])
    assert len(car) == 1 and "accepted: 68 (iBUG-68) or 51" in car[0]  # the sizes need the points
    files["car"]["landmarks"] = d / "n.pts"
    assert "image is 160x110 (WxH)" in take_file_problems("range", files["car"])[0]
    (d / "car.pts").write_text("garbage")
    files["car"]["landmarks"] = d / "car.pts"
    car_bad = take_file_problems("range", files["car"])
    rows = [
        dict(take="n", kind="neutral", modality="range"),
        dict(take="car", kind="viseme", modality="range"),
        dict(take="too", kind="viseme", modality="range"),
        dict(take="lidar", kind="viseme", modality="lidar"),
    ]

    def takes(rows, files):
        return [
            Take.from_row(r | dict(subject="s", label=r["take"]), files=files[r["take"]])
            for r in rows
        ]

    files["lidar"] = {}
    sheet = [("lidar", "sheet row 5 (s/lidar): modality 'lidar' unknown")]
    assert check.run(None, takes(rows, files)[1], check.Params()).files["problems"] == car_bad
    report = check.check_subject("s", takes(rows, files), sheet)
    assert set(report["takes"]) == {"car", "too", "lidar"}
    assert "mirrored (left-handed) frame" in report["takes"]["too"][0]
    assert check.take_problem(report, "lidar") == sheet[0][1]
    assert check.take_problem(report, "n") == ""
    # the neutral's problem stops the subject, after every problem was logged
    files["n"]["landmarks"] = d / "car.pts"
    with pytest.raises(InputError, match=r"4 problems .*its neutral take n cannot be read"):
        check.check_subject("s", takes(rows, files), sheet)
    with pytest.raises(InputError, match="1 problem .*sheet rows are inconsistent"):
        one = {"n": files["too"] | {"xyz": d / "n.abs.gz"}}
        check.check_subject("s", takes(rows[:1], one), [("", "dup")])


def test_a_mirrored_frame_is_refused_and_a_rotated_one_kept(take):
    xyz, lm = take["xyz"], take["landmarks"]
    depth = check_handedness(xyz, lm, "car.abs.gz")
    assert -40 < depth < -10  # the nose tip 10-40 mm in front of the eyes' and mouth's plane
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rotation = q * np.sign(np.linalg.det(q))  # a proper rotation: any right-handed frame
    moved = xyz @ rotation.T + [100.0, -50.0, 20.0]
    # (the lift is a per-coordinate median: a rotation moves it a little)
    assert check_handedness(moved, lm, "car.abs.gz") == pytest.approx(depth, abs=3.0)
    for mirrored in (xyz[..., [1, 0, 2]], xyz * [-1.0, 1.0, 1.0], moved[..., [0, 2, 1]]):
        with pytest.raises(InputError, match=r"^car.abs.gz: xyz: a mirrored \(left-handed\)"):
            check_handedness(mirrored, lm, "car.abs.gz")
    assert np.isnan(check_handedness(np.full_like(xyz, np.nan), lm, "car.abs.gz"))


@pytest.fixture
def full_disk(tmp_path):
    """A 256 KiB tmpfs: a real full disk (root only; CI runs as root)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mount)], capture_output=True
    )
    if done.returncode:
        if os.environ.get("CI"):
            pytest.fail(f"cannot mount a tmpfs under CI: {done.stderr.decode().strip()}")
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=True)


def test_a_full_disk_is_one_line_from_every_writer(full_disk):
    kept = full_disk / "kept.h5"
    write_part(kept, {"/a": np.arange(3.0)})
    big = {"/a": np.random.default_rng(0).random((300, 300))}  # 720 kB of noise
    with pytest.raises(OutputError, match=f"^no space left on device writing {kept}$"):
        write_part(kept, big)
    np.testing.assert_array_equal(read_part(kept)["/a"], np.arange(3.0))  # left as it was
    assert sorted(p.name for p in full_disk.iterdir()) == ["kept.h5"]  # no temporary left
    with pytest.raises(OutputError, match="no space left on device writing .*big.png$"):
        write_color(
            full_disk / "big.png",
            (255 * np.random.default_rng(0).random((400, 400, 3))).astype(np.uint8),
        )
    # the other writers of a job's outputs: meshes, JSON, tables
    from scan2morph.io import write_obj
    from scan2morph.jobs import write_json
    from scan2morph.tables import Column, write_table

    v, f = np.random.default_rng(2).random((20000, 3)), np.zeros((1, 3), dtype=np.int64)
    with pytest.raises(OutputError, match="no space left on device writing .*m.obj$"):
        write_obj(full_disk / "m.obj", v, f)
    with pytest.raises(OutputError, match="no space left on device writing .*a.json$"):
        write_json(full_disk / "a.json", {"x": list(range(100000))})
    import pandas as pd

    table = pd.DataFrame({"x": np.arange(50000.0)})
    with pytest.raises(OutputError, match="no space left on device writing .*t.tsv$"):
        write_table(full_disk / "t.tsv", table, [Column("x", "mm", "a value")])
    for name in ("m.obj", "a.json", "t.tsv"):
        (full_disk / name).unlink(missing_ok=True)
    # a job: one line on stderr, no HDF5 finaliser tracebacks, exit status 1
    script = textwrap.dedent(
        f"""
        import numpy as np
        from scan2morph.jobs import run_job
        from scan2morph.store import merge_parts, write_part

        def job():
            write_part({str(full_disk / "p.h5")!r}, {{"/x": np.zeros(10)}})
            write_part({str(full_disk / "q.h5")!r}, {{"/b": np.random.default_rng(1).random(90000)}})

        run_job(None, job)
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].endswith(
        f"no space left on device writing {full_disk / 'q.h5'}"
    )
    assert Path(full_disk / "p.h5").is_file()


@pytest.mark.slow
def test_accuracy_and_cohort_name_the_takes_left_out(tmp_path_factory, tmp_path, caplog):
    """On the tiny run's synthetic subject with one viseme left out: accuracy.json lists it under
    ``failed_takes`` and measures the rest as before; the cohort table names it."""
    import json
    import shutil

    from scan2morph.evaluate.truth import read_truth
    from scan2morph.report import write_cohort_summary
    from scan2morph.stages import accuracy
    from scan2morph.template import load_template
    from tests.support.tiny_run import SUBJECT, TAKES, tiny_run

    run = tiny_run(tmp_path_factory, [f"results/{SUBJECT}/accuracy.json"])
    store = read_part(run.path("results", SUBJECT, f"{SUBJECT}.h5"))
    record = Failure("too", "fit", "s/too: the template folds")
    data = {k: v for k, v in store.items() if "/too/" not in k and not k.startswith("/pca")}
    data |= record.datasets()
    kinds = {t["take"]: t["kind"] for t in TAKES}
    subject = Subject(SUBJECT, kinds, {t["take"]: t["label"] for t in TAKES})
    truths = {
        t: read_truth(run.path("results", "synthetic", SUBJECT, "truth", f"{t}.npz")) for t in kinds
    }
    params = accuracy.Params.from_config(run_config(run))
    template = load_template(run.path("resources", "template.npz"))
    data |= accuracy.truth_datasets(truths)
    report = accuracy.run(template, subject, data, params).files["accuracy"]
    assert report["failed_takes"] == {"too": {"stage": "fit", "reason": record.reason}}
    assert "too" not in report["takes"]
    before = json.loads(run.path("results", SUBJECT, "accuracy.json").read_text())
    assert before["failed_takes"] == {}
    assert report["takes"]["car"]["motion"] == before["takes"]["car"]["motion"]
    # the cohort table and the cohort job's console lines name it
    copy = tmp_path / f"{SUBJECT}.h5"
    shutil.copy(run.path("results", SUBJECT, f"{SUBJECT}.h5"), copy)
    with h5py.File(copy, "a") as h5:
        for key, value in record.datasets().items():
            h5.create_dataset(key, data=value, dtype=h5py.string_dtype())
    from scan2morph import load_model

    model = load_model(copy)
    assert model.failed == {"too": record}  # the model API names it too
    # its repr is one line of what it holds, not its arrays
    text = repr(model)
    assert text.startswith(f"Model({SUBJECT!r}: {len(model.neutral)} vertices, ")
    assert "left out ['too']" in text and "\n" not in text and len(text) < 400
    with caplog.at_level("INFO", logger="scan2morph"):
        table = write_cohort_summary({SUBJECT: copy}, {}, tmp_path / "t.tsv", tmp_path / "t.png")
    assert table["left_out"].tolist() == ["too (fit)"]
    # in the cohort job's log, not on the console: the run's last lines print it once
    line = f"{SUBJECT}/too left out at fit: s/too: the template folds"
    assert [r.levelname for r in caplog.records if line in r.getMessage()] == ["INFO"]


def run_config(run):
    """The tiny run's merged config sections (repo config under the run's)."""

    config = load_yaml(run.configfiles[0])
    for key, value in load_yaml(run.configfile).items():
        config[key] = value
    return config
