# Shared tables: config validation, the subject sheet, the synthetic cohort and the take table,
# and lookups over them by subject. Included first; the other helper files and the rules use these.
import os
import shutil
import sys
import time
from pathlib import Path

import pandas as pd

from scan2morph.config_schema import validate_config
from scan2morph.errors import InputError
from scan2morph.io.yaml_text import config_file_problem
from scan2morph.jobs import config_sha256, memory_mb
from scan2morph.sheet import read_sheet, sheet_problems, synthetic_rows, take_table
from scan2morph.sheet_consistency import blend_label_problem
from scan2morph.stages.stage_job import SUBJECT_STAGES, check_stage_params
from scan2morph.template.mesh import FIDUCIAL_SETS

SCHEMAS = Path(workflow.basedir) / "schemas"


def drop_stale_backups(backups=Path(".snakemake") / "backups"):
    """Remove the copies of a killed run's outputs (README: after `snakemake --unlock` the run
    goes on from where it stopped). Snakemake copies a job's update() outputs there while the job
    runs and removes them when it ends; a killed job leaves them, and Snakemake cannot copy a
    folder output over its old copy (FileExistsError at the job's start). Called before any job
    of the run (onstart, under the run's lock): a killed stage re-runs all the same, as its
    fingerprint leaves stages.json before it runs (scan2morph.stages.stage_job.run_stages).
    """
    if backups.exists():
        # the folders a finished job's copies were in stay behind, empty: no message for those
        left = any(path.is_file() for path in backups.rglob("*"))
        shutil.rmtree(backups)
        if left:
            sys.stderr.write(
                f"removed {backups}: a killed run's copies of its outputs\n"
            )


def stop_run(exc):
    """Stop the whole run on a config or sheet error (an exception or its line): one line, no
    traceback."""
    sys.stderr.write(f"Error: {exc}\n")
    sys.exit(1)


# the config files Snakemake read (config/config.yaml, each --configfile) read as
# tools/check_config.py reads them, once a run: a key given twice, which Snakemake takes
# silently (the last value), is the same line on every entry point, not only under make run
if workflow.is_main_process:
    for _file in workflow.configfiles:
        if _problem := config_file_problem(_file):
            stop_run(_problem)
try:
    validate_config(config, SCHEMAS / "config.schema.yaml", source="config")
    # once a run, not again in each cluster job's Snakemake
    if workflow.is_main_process:
        check_stage_params(config)
except InputError as _exc:
    stop_run(_exc)

SYNTH_ROOT = "results/synthetic"
SYNTH_TAKES = [t["take"] for t in config["synthetic"]["takes"]]
LAYOUT = str(Path(workflow.basedir) / "schemas" / "store.layout.yaml")
try:
    SHEET = read_sheet(config["subjects"])
    SYNTH = synthetic_rows(
        config["synthetic"]["subjects"],
        config["synthetic"]["prefix"],
        config["synthetic"]["takes"],
        SYNTH_ROOT,
        config["synthetic"]["stereo"],
        config["synthetic"]["mesh"],
        config["synthetic"]["rgbd"],
        config["synthetic"]["landmarks"],
    )
    TAKES = take_table(SHEET, SYNTH)
    if _problem := blend_label_problem(config["morph"]["blends"], TAKES["label"]):
        raise InputError("config", _problem)
except InputError as _exc:
    stop_run(_exc)
SUBJECTS = list(dict.fromkeys(TAKES["subject"]))
if not SUBJECTS:  # else the run does nothing and says nothing
    stop_run(
        InputError(
            config["subjects"],
            "no takes: the sheet has no rows (only its header or comments) and "
            "synthetic.subjects is 0, so there is nothing to run",
        )
    )
# a row that breaks the sheet's schema (e.g. an empty label): its take is left out (its subject
# stops when it is the neutral's); reported with the files' problems by the subject's check job
PROBLEMS = sheet_problems(
    pd.concat([SHEET, SYNTH]),
    schema=SCHEMAS / "sheet.schema.yaml",
    reserved=[*config["morph"]["blends"], *config["morph"]["pca_blends"]],
)
# a subject job's trigger on the config (its stages' fingerprints decide what runs): the sweep
# table's path and the sheet's reach no subject stage (a take's rows and files are its jobs' own
# inputs), and switching tables or moving the sheet re-ran every subject
CONFIG_SHA256 = config_sha256(config, ["sweeps", "subjects"])
# when this run started: a job log written since is this run's (report_left_out)
RUN_START = time.time()


# --- lookups in the take table ---
# the subjects whose every take is synthetic (they have ground truth), found once: jobs' params
# and wildcard constraints ask for them, and every Snakemake a SLURM job starts parses them
_ALL_SYNTHETIC = TAKES.groupby(level=0, sort=False)["synthetic"].all()
_SYNTHETIC = [s for s in SUBJECTS if _ALL_SYNTHETIC[s]]


def synthetic_subjects():
    return _SYNTHETIC


def measured_subjects():
    """The subjects without ground truth (every one not synthetic)."""
    return [s for s in SUBJECTS if not _ALL_SYNTHETIC[s]]


def takes_of(subject):
    """Take ids of a subject (first row of a duplicate)."""
    return list(TAKES.loc[subject, "take"])


def takes_of_kind(subject, kind):
    rows = TAKES.loc[subject]
    return list(rows.loc[rows["kind"] == kind, "take"])


def _take_files(pattern, subject, takes):
    return expand(pattern, subject=subject, take=takes)


# --- the synthetic cohort (declares the generator rules of synth.smk) ---
def synth_groups():
    """Synthetic subjects grouped by which of their takes are stereo pairs, one generator job per group:
    dicts with the rule ``name``, the ``subjects`` and their ``takes`` (take, kind, label,
    modality), the group with the fewest stereo takes first."""
    groups = {}
    for subject, rows in SYNTH.groupby("subject", sort=False):
        takes = rows[["take", "kind", "label", "modality"]].to_dict("records")
        key = tuple(t["modality"] for t in takes)
        groups.setdefault(key, {"subjects": [], "takes": takes})["subjects"].append(
            subject
        )
    out = sorted(
        groups.values(),
        key=lambda g: sum(t["modality"] == "stereo" for t in g["takes"]),
    )
    names = set()
    for group in out:
        base = (
            "synth_stereo_subject"
            if any(t["modality"] == "stereo" for t in group["takes"])
            else "synth_subject"
        )
        name, k = base, 2
        while name in names:
            name, k = f"{base}_{k}", k + 1
        names.add(name)
        group["name"] = name
    return out


def synth_files(pattern, takes, modality=None):
    """``pattern`` expanded over the takes (of one modality), with ``{subject}`` kept."""
    return [
        pattern.format(subject="{subject}", take=t["take"])
        for t in takes
        if modality in (None, t["modality"])
    ]


def report_left_out():
    """The run's last console lines: every subject its check or its own job stopped in this run,
    and why (its store and report, if any, are an earlier run's: :func:`flag_earlier_run`);
    every take left out of its subject (from the stores made). Returns the subjects stopped:
    subject -> why (and that its files are an earlier run's, for the cohort summary's column).
    """
    import h5py

    from scan2morph.jobs import job_error
    from scan2morph.store.warnings import read_failures

    stopped = {}
    for subject in SUBJECTS:
        store = Path(f"results/{subject}/{subject}.h5")
        if error := job_error(stop_logs(subject), RUN_START):
            why, log = error
            earlier = flag_earlier_run(subject, why, log) if store.is_file() else ""
            stopped[subject] = why + earlier
            sys.stderr.write(f"stopped: {subject}: {why} ({log}){earlier}\n")
        elif store.is_file():
            with h5py.File(store, "r") as h5:
                for failure in read_failures(h5).values():
                    sys.stderr.write(f"left out: {subject}/{failure}\n")
    clear_current_reports(stopped)
    return stopped


def flag_earlier_run(subject, why, log):
    """A subject that stopped keeps its earlier run's files (none is deleted): a banner at the top
    of its report.html says they are out of date, when and why it stopped. Returns the note
    for the console line."""
    from scan2morph.report import mark_stale

    started = time.strftime("%Y-%m-%d %H:%M", time.localtime(RUN_START))
    note = (
        f"Out of date: {subject} stopped in the run of {started}: {why} ({log}). This page, the "
        "store and the other files beside it are an earlier run's; they are made again once "
        "the subject runs through."
    )
    if mark_stale(f"results/{subject}/report.html", note):
        return " (its store and report are an earlier run's: report.html says so at its top)"
    return " (its store and report are an earlier run's)"


def clear_current_reports(stopped):
    """Take :func:`flag_earlier_run`'s banner off the report of every subject whose files are
    current again: not stopped in this run, no job of it left to run, its check and its job
    finished (``check.json``, ``job.json``: a failed check or subject job leaves none). The
    subject's job takes it off too when it runs; a mended neutral whose parts come out the same
    runs none."""
    from scan2morph.report import clear_stale

    left = pending_subjects()
    for subject in SUBJECTS:
        done = (f"results/{subject}/check.json", f"results/{subject}/job.json")
        if (
            subject not in stopped
            and subject not in left
            and all(map(os.path.isfile, done))
        ):
            clear_stale(f"results/{subject}/report.html")


def pending_subjects():
    """The subjects with a job that was due in this run and did not finish (their files are an
    earlier run's)."""
    pending = workflow.dag.needrun_jobs()
    return {
        job.wildcards.get("subject") for job in pending if "subject" in job.wildcards
    }


def stop_logs(subject):
    """The logs that say why a subject stopped: its check's, and that of the stage its job
    stopped at (the job's own log lists its stages, the last ``{stage}: failed``)."""
    logs = [f"logs/check_subject/{subject}.log"]
    summary = Path(f"logs/subject/{subject}.log")
    last = summary.read_text().splitlines()[-1:] if summary.is_file() else []
    if last and last[0].endswith(": failed"):
        logs.append(f"logs/{last[0].removesuffix(': failed')}/{subject}.log")
    return logs


def subject_finished(subject):
    """The subject's store is this run's: its job and every take's finished (their job.json:
    a failed job leaves none) and, for a synthetic subject, its accuracy is written."""
    files = [f"results/{subject}/{subject}.h5", f"results/{subject}/job.json"]
    files += _take_files(
        "results/{subject}/takes/{take}/job.json", subject, takes_of(subject)
    )
    if subject in synthetic_subjects():
        files.append(f"results/{subject}/accuracy.json")
    return all(Path(f).is_file() for f in files)


def summarise_finished_subjects(stopped):
    """When subjects stopped and so the cohort summary could not run: the summary of those that
    finished, with a row for each other saying why (``stopped``: subject -> why, from
    :func:`report_left_out`), so that one bad subject does not hold back the others'."""
    import json
    import logging

    from scan2morph.errors import InputError
    from scan2morph.report import write_cohort_summary

    # the jobs that were due and did not finish
    if not any(job.rule.name == "cohort" for job in workflow.dag.needrun_jobs()):
        return  # not asked for in this run, or written
    left = pending_subjects()  # their files are an earlier run's
    done = [
        s
        for s in SUBJECTS
        if s not in stopped and s not in left and subject_finished(s)
    ]
    why = "not finished in this run (a job of it or before it failed, or the run was stopped)"
    others = {s: stopped.get(s, why) for s in SUBJECTS if s not in done}
    if not others:  # every subject finished: the cohort job failed on its own
        return
    accuracy = {
        s: json.loads(Path(f"results/{s}/accuracy.json").read_text())
        for s in done
        if s in synthetic_subjects()
    }
    quiet = logging.getLogger("scan2morph")  # its left-out takes: listed above already
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    outputs = ("results/cohort/summary.tsv", "results/cohort/summary.png")
    try:
        write_cohort_summary(
            {s: f"results/{s}/{s}.h5" for s in done}, accuracy, *outputs, others
        )
    except InputError as exc:
        sys.stderr.write(f"cohort: not written: {exc}\n")
        return
    finally:
        quiet.setLevel(level)
    for path in outputs:  # provisional: the cohort job writes it again once it can run
        os.utime(path, (0, 0))
    sys.stderr.write(
        f"cohort: results/cohort/summary.tsv summarises the {len(done)} subjects that finished; "
        f"stopped: {', '.join(others)} (its column 'stopped' says why)\n"
    )
