"""Several stages in one job (one per take, one per subject): the stages' fingerprints (which of
them re-run), the job's run of its stages and their benchmark files.

The jobs themselves (a config change re-running only the stages it reaches, take isolation, the
per-stage benchmark files of a run) are tested end to end in ``tests/workflow/test_workflow.py``.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import pandas as pd
import pytest

from scan2morph.jobs import files_sha256, sha256_file
from scan2morph.report.provenance import stage_timings
from scan2morph.sheet import validate_config
from scan2morph.stages import (
    accuracy,
    align,
    fit,
    ingest,
    landmarks,
    modal,
    morph,
    motion,
    motion_noise,
    refine,
    repair,
    report,
    store,
)
from scan2morph.stages.stage_job import (
    BENCHMARK_COLUMNS,
    JOB_CODE,
    STAGE_CODE,
    SUBJECT_STAGES,
    TAKE_STAGES,
    benchmarked,
    code_fingerprints,
    fingerprint,
    part_fingerprint,
    read_fingerprints,
    run_stages,
    stage_code,
    up_to_date,
    write_benchmark,
    write_fingerprints,
)
from tests.support.configs import repo_config

ROOT = Path(__file__).resolve().parents[2]
MODULES = (ingest, repair, landmarks, fit, align, refine)
SUBJECT_MODULES = (motion, motion_noise, morph, modal, store, accuracy, report)


@pytest.fixture(scope="module")
def config():
    config = repo_config()
    return validate_config(config, ROOT / "schemas" / "config.schema.yaml")


def test_a_fingerprint_depends_on_the_params_and_the_reads_not_on_their_order(config):
    reads = {"take": {"kind": "viseme", "neutral": "n"}, "ingest": "ab" * 32}
    base = fingerprint("repair", repair.Params.from_config(config), reads)
    assert len(base) == 64 and int(base, 16) >= 0
    # the same in any key order and from a fresh Params
    again = dict(reversed(list(reads.items())))
    assert fingerprint("repair", repair.Params.from_config(config), again) == base
    # any change of the section, of what it reads or of the stage's name gives another
    changed = {**config, "repair": {**config["repair"], "max_hole_px": 401}}
    assert fingerprint("repair", repair.Params.from_config(changed), reads) != base
    assert fingerprint("repair", repair.Params.from_config(config), reads | {"ingest": "0"}) != base
    assert fingerprint("fit", repair.Params.from_config(config), reads) != base


def test_every_stage_params_has_a_stable_fingerprint(config):
    """Nested dataclasses, tuples and numbers are taken apart: no object address (a repr of an
    object) reaches the fingerprint, so two builds of the Params agree."""
    for module in MODULES + SUBJECT_MODULES:
        a = fingerprint(module.__name__, module.Params.from_config(config), {})
        b = fingerprint(module.__name__, module.Params.from_config(dict(config)), {})
        assert a == b, module.__name__


def test_a_stage_is_up_to_date_only_with_its_fingerprint_and_all_its_files(tmp_path):
    record = tmp_path / "stages.json"
    assert read_fingerprints(record) == {}  # no record: every stage runs
    write_fingerprints(record, {"ingest": "a", "repair": "b"})
    assert read_fingerprints(record) == {"ingest": "a", "repair": "b"}
    part, report = tmp_path / "repair.h5", tmp_path / "repair.json"
    part.write_bytes(b"x")
    assert not up_to_date(read_fingerprints(record), "repair", "b", [part, report])
    report.write_text("{}")
    assert up_to_date(read_fingerprints(record), "repair", "b", [part, report])
    assert not up_to_date(read_fingerprints(record), "repair", "c", [part, report])
    assert not up_to_date(read_fingerprints(record), "fit", "b", [part])
    folder = tmp_path / "models"  # an output folder counts as a file
    folder.mkdir()
    assert up_to_date(read_fingerprints(record), "repair", "b", [part, folder])
    record.write_text("not json")
    assert read_fingerprints(record) == {}


def test_a_part_of_another_job_is_known_by_its_recorded_fingerprint_or_its_bytes(tmp_path):
    part = tmp_path / "takes" / "car" / "fit.h5"
    part.parent.mkdir(parents=True)
    part.write_bytes(b"fitted")
    assert part_fingerprint(part) == sha256_file(part)  # no record: the bytes
    write_fingerprints(part.parent / "stages.json", {"fit": "f" * 64, "align": "a" * 64})
    assert part_fingerprint(part) == "f" * 64
    assert part_fingerprint(part.with_name("align.h5")) == "a" * 64


def _job(tmp_path, prints, fail=None):
    """A job of three stages, a -> b -> c (each one's print: its own setting and what it
    reads); returns the stages it ran and the job's log."""
    ran = []

    def plan(stage, done):
        reads = {"a": {}, "b": {"a": done.get("a")}, "c": {"b": done.get("b")}}[stage]
        return fingerprint(stage, {"setting": prints[stage]}, reads), [tmp_path / f"{stage}.out"]

    def run(stage):
        if stage == fail:
            raise SystemExit(1)  # a stage's bad input (scan2morph.jobs.run_job)
        (tmp_path / f"{stage}.out").write_text(stage)
        ran.append(stage)

    log = tmp_path / "job.log"
    benchmarks = {s: tmp_path / "bench" / f"{s}.tsv" for s in ("a", "b")}
    done = tmp_path / "job.json"
    done.unlink(missing_ok=True)  # a plain output: Snakemake deletes it when the job starts
    run_stages("abc", plan, run, tmp_path / "stages.json", log, benchmarks, done)
    return ran, log.read_text().splitlines()


def test_a_job_runs_only_the_stages_a_change_reaches(tmp_path):
    prints = {"a": 1, "b": 1, "c": 1}
    assert _job(tmp_path, prints)[0] == ["a", "b", "c"]
    assert set(read_fingerprints(tmp_path / "stages.json")) == {"a", "b", "c"}
    # benchmark files where given (c has none)
    assert sorted(p.name for p in (tmp_path / "bench").iterdir()) == ["a.tsv", "b.tsv"]
    ran, log = _job(tmp_path, prints)
    assert ran == [] and log == [f"{s}: up to date, not run" for s in "abc"]
    # b's setting: b and what reads it (c) run, a is kept
    ran, log = _job(tmp_path, prints | {"b": 2})
    assert ran == ["b", "c"]
    assert log == ["a: up to date, not run", "b: run", "c: run"]
    # the record of the finished run: the stages' fingerprints, the same bytes after a run
    # that changed nothing (what reads it is not run again)
    record = (tmp_path / "job.json").read_bytes()
    assert json.loads(record) == {"stages": read_fingerprints(tmp_path / "stages.json")}
    assert _job(tmp_path, prints | {"b": 2})[0] == []
    assert (tmp_path / "job.json").read_bytes() == record
    # c's setting: c alone; an output gone: its stage alone (made from the same, it has the
    # same fingerprint: what reads it is kept)
    assert _job(tmp_path, prints | {"b": 2, "c": 2})[0] == ["c"]
    (tmp_path / "b.out").unlink()
    assert _job(tmp_path, prints | {"b": 2, "c": 2})[0] == ["b"]


def test_a_failed_stage_stops_the_job_and_runs_again_next_time(tmp_path):
    prints = {"a": 1, "b": 1, "c": 1}
    _job(tmp_path, prints)
    with pytest.raises(SystemExit):
        _job(tmp_path, prints | {"a": 2}, fail="b")
    log = (tmp_path / "job.log").read_text().splitlines()
    assert log == ["a: run", "b: failed"]  # c after it not run
    # no record of a finished run: the workflow runs the job again (its update() files, put
    # back by Snakemake with a new time, would otherwise be taken for current)
    assert not (tmp_path / "job.json").exists()
    # b's record is gone (its old output is not taken for the new one), a's is the new one
    recorded = read_fingerprints(tmp_path / "stages.json")
    assert "b" not in recorded and set(recorded) == {"a", "c"}
    assert _job(tmp_path, prints | {"a": 2})[0] == ["b", "c"]


def test_benchmark_files_read_as_snakemake_s(tmp_path):
    path = tmp_path / "rules" / "refine" / "s1" / "car.tsv"
    write_benchmark(path, 3725.25, 1.5, 210.0)
    table = pd.read_csv(path, sep="\t")
    assert tuple(table.columns) == BENCHMARK_COLUMNS
    row = table.iloc[0]
    assert (row["s"], row["h:m:s"], row["cpu_time"], row["max_rss"]) == (
        3725.25,
        "1:02:05",
        1.5,
        210.0,
    )
    assert row["mean_load"] == pytest.approx(100 * 1.5 / 3725.25, abs=0.01)
    assert pd.isna(row["max_vms"])
    # the report's run-time table counts it as the rule's job
    (rows,) = stage_timings(tmp_path / "rules", "s1")
    assert (rows["stage"], rows["jobs"], rows["seconds"]) == ("refine", 1, 3725.25)


def test_a_timed_block_records_its_own_wall_and_cpu_time(tmp_path):
    path = tmp_path / "b.tsv"
    t0 = time.perf_counter()
    with benchmarked(path):
        end = time.process_time() + 0.05
        while time.process_time() < end:  # 50 ms of CPU
            pass
        time.sleep(0.05)  # and 50 ms of waiting
    wall = time.perf_counter() - t0
    row = pd.read_csv(path, sep="\t").iloc[0]
    assert 0.1 <= row["s"] <= wall + 1e-3
    assert 0.05 <= row["cpu_time"] <= 0.05 + 0.03
    assert row["max_rss"] > 1.0  # MB: this process's peak while the block ran
    with pytest.raises(ZeroDivisionError), benchmarked(path):  # written on an error too
        raise ZeroDivisionError
    assert pd.read_csv(path, sep="\t").iloc[0]["s"] < 0.05


#: Stages whose code fingerprints the tests below compare (a representative few: the store's
#: covers the modules of every stage that makes it).
CODE_STAGES = ("ingest", "repair", "refine", "morph", "modal", "store", "report_subject")


@pytest.fixture
def library_copy(tmp_path):
    """A copy of the library in ``tmp_path/src/scan2morph`` (its folder), without the viewer
    bundle beside it (``tmp_path/tools``)."""
    from scan2morph.provenance import PACKAGE_DIR

    copy = tmp_path / "src" / "scan2morph"
    shutil.copytree(PACKAGE_DIR, copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def test_a_code_change_re_runs_the_stages_that_run_it_and_no_other(library_copy):
    """A change of code in ``scan2morph.morph.pca`` changes the code fingerprint of morph, of the
    store (made from morph's part) and of the report (which reads the PCA tables), not those
    of the take stages or the modal stage; a docstring or comment edit changes none."""
    before = code_fingerprints(CODE_STAGES, library_copy)
    assert len(set(before.values())) == len(CODE_STAGES)
    pca = library_copy / "morph" / "pca.py"
    text = pca.read_text()
    first = text.index('"""', text.index("def ")) + 3  # into the first function's docstring
    edited = text[:first] + "Edited docstring. " + text[first:] + "\n# a comment\n"
    pca.write_text(edited)
    assert code_fingerprints(CODE_STAGES, library_copy) == before
    pca.write_text(edited + "\nEXTRA_CONSTANT = 1\n")
    after = code_fingerprints(CODE_STAGES, library_copy)
    changed = {s for s in CODE_STAGES if after[s] != before[s]}
    assert changed == {"morph", "store", "report_subject"}


def test_the_jobs_outside_takes_and_subjects_follow_their_code(library_copy):
    """The synthetic subjects' generator, the template's builder and the cohort's summary: a
    change to the code they run re-runs them (a changed generator regenerated nothing, so the
    default cohort kept the old scans). The generator's reaches no take's or subject's stage
    (the landmark detector's writer imported it, so every take's landmarks, and all after them,
    followed the generator's code)."""
    jobs = [*JOB_CODE, *CODE_STAGES]
    before = code_fingerprints(jobs, library_copy)
    skin = library_copy / "synth" / "skin.py"
    skin.write_text(skin.read_text() + "\nEXTRA_CONSTANT = 1\n")
    after = code_fingerprints(jobs, library_copy)
    assert {s for s in jobs if after[s] != before[s]} == {"synth"}  # no take's, no subject's
    mesh = library_copy / "template" / "mesh.py"
    mesh.write_text(mesh.read_text() + "\nEXTRA_CONSTANT = 1\n")
    again = code_fingerprints(jobs, library_copy)
    assert {"template", "ingest", "refine"} <= {s for s in jobs if again[s] != after[s]}
    assert again["cohort"] == after["cohort"]


def test_the_reports_fingerprint_follows_the_viewer_bundle(library_copy):
    """A report written without the 3D viewer is written again once the bundle is there, and
    again when it is rebuilt differently; no other stage re-runs for it."""
    from scan2morph.provenance import repository_dir

    without = code_fingerprints(CODE_STAGES, library_copy)
    bundle = repository_dir(library_copy) / "tools" / "viewer" / "dist" / "viewer.js"
    bundle.parent.mkdir(parents=True)
    bundle.write_text("export const viewer = 1;\n")
    built = code_fingerprints(CODE_STAGES, library_copy)
    bundle.write_text("export const viewer = 2;\n")
    rebuilt = code_fingerprints(CODE_STAGES, library_copy)
    assert len({without["report_subject"], built["report_subject"], rebuilt["report_subject"]}) == 3
    for stage in set(CODE_STAGES) - {"report_subject"}:
        assert without[stage] == built[stage] == rebuilt[stage]


def test_package_data_re_runs_the_stages_that_read_it(library_copy):
    """The landmark detector's model (``landmarks/model.npz``) and the report's templates are
    part of the code of the stages that use them."""
    stages = ("landmarks", *CODE_STAGES)
    before = code_fingerprints(stages, library_copy)
    with open(library_copy / "landmarks" / "model.npz", "ab") as f:
        f.write(b"\0")
    after = code_fingerprints(stages, library_copy)
    assert {s for s in stages if after[s] != before[s]} == {"landmarks", "store"}
    (library_copy / "report" / "templates" / "report.css").write_text("body {}\n")
    again = code_fingerprints(stages, library_copy)
    assert {s for s in stages if again[s] != after[s]} == {"report_subject"}


def test_every_stage_names_the_modules_it_runs():
    from scan2morph.provenance import module_file

    assert set(STAGE_CODE) == {*TAKE_STAGES, *SUBJECT_STAGES}
    assert not set(JOB_CODE) & set(STAGE_CODE)
    for stage in [*STAGE_CODE, *JOB_CODE]:
        assert all(module_file(m) for m in stage_code(stage)), stage
    # the store's code is that of every stage that makes what it holds
    assert set(stage_code("morph")) | set(stage_code("ingest")) <= set(stage_code("store"))


def test_a_folder_named_as_an_input_is_checksummed_by_its_files(tmp_path):
    """A depth folder that holds no frame reaches the checks as the folder (they say why the take
    is left out): its checksum is its files' names and contents, and reading it as a file
    (IsADirectoryError) stopped the subject's check job with a traceback."""
    folder = tmp_path / "depth"
    folder.mkdir()
    (folder / "notes.txt").write_text("no frames\n")
    one = tmp_path / "one.png"
    one.write_bytes(b"png")
    before = files_sha256({"depth": [str(folder)], "color": str(one)})
    assert before["color"] == [sha256_file(one)] and len(before["depth"][0]) == 64
    assert files_sha256({"depth": [folder]}) == {"depth": before["depth"]}
    (folder / "notes.txt").write_text("no frames yet\n")
    assert files_sha256({"depth": [folder]})["depth"] != before["depth"]
