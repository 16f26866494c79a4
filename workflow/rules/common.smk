# Shared tables: config validation, the subject sheet, the synthetic cohort and the take table,
# and lookups over them by subject. Included first; the other helper files and the rules use these.
from pathlib import Path

import sys
import time

import pandas as pd

from scan2morph.config_schema import validate_config
from scan2morph.errors import InputError
from scan2morph.jobs import config_sha256, memory_mb
from scan2morph.sheet import read_sheet, sheet_problems, synthetic_rows, take_table
from scan2morph.stages.stage_job import SUBJECT_STAGES, check_take_params
from scan2morph.template.mesh import FIDUCIAL_SETS

SCHEMAS = Path(workflow.basedir) / "schemas"


def stop_run(exc):
    """Stop the whole run on a config or sheet error: one line, no traceback."""
    sys.stderr.write(f"Error: {exc}\n")
    sys.exit(1)


try:
    validate_config(config, SCHEMAS / "config.schema.yaml", source="config")
    # once a run, not again in each cluster job's Snakemake
    if workflow.is_main_process:
        check_take_params(config)
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
    pd.concat([SHEET, SYNTH]), schema=SCHEMAS / "sheet.schema.yaml"
)
# a subject job's trigger on the config (its stages' fingerprints decide what runs): the sweep
# table's path reaches no subject stage, and switching tables re-ran every subject
CONFIG_SHA256 = config_sha256(config, ["sweeps"])
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
    and why (its store, report and cohort row, if any, are an earlier run's); every take left
    out of its subject (from the stores made)."""
    import h5py

    from scan2morph.jobs import job_error
    from scan2morph.store.warnings import read_failures

    for subject in SUBJECTS:
        store = Path(f"results/{subject}/{subject}.h5")
        logs = [f"logs/check_subject/{subject}.log", f"logs/subject/{subject}.log"]
        if stopped := job_error(logs, RUN_START):
            earlier = " (its store, report and cohort row are an earlier run's)"
            message, log = stopped
            sys.stderr.write(
                f"stopped: {subject}: {message} ({log}){earlier if store.is_file() else ''}\n"
            )
        elif store.is_file():
            with h5py.File(store, "r") as h5:
                for failure in read_failures(h5).values():
                    sys.stderr.write(f"left out: {subject}/{failure}\n")
