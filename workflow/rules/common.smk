# Helpers shared by the rules: config and sheet loading, input functions, wildcard constraints.
import logging
from pathlib import Path

import pandas as pd

from snakemake.utils import validate

from scan2morph.jobs import config_sha256
from scan2morph.sheet import read_sheet, subject_problems, synthetic_rows, take_table


validate(config, "../../schemas/config.schema.yaml")

SYNTH_ROOT = "results/synthetic"
SYNTH_TAKES = [t["take"] for t in config["synthetic"]["takes"]]
LAYOUT = str(Path(workflow.basedir) / "schemas" / "store.layout.yaml")
SHEET = read_sheet(config["subjects"])
for _i, _row in enumerate(SHEET.to_dict("records")):
    validate(_row, "../../schemas/sheet.schema.yaml")
SYNTH = synthetic_rows(
    config["synthetic"]["subjects"],
    config["synthetic"]["prefix"],
    config["synthetic"]["takes"],
    SYNTH_ROOT,
)
TAKES = take_table(SHEET, SYNTH)
SUBJECTS = list(dict.fromkeys(TAKES["subject"]))
PROBLEMS = subject_problems(pd.concat([SHEET, SYNTH]))
for _subject, _problems in PROBLEMS.items():
    for _problem in _problems:
        logging.getLogger("snakemake").warning(f"subject {_subject} will fail: {_problem}")
CONFIG_SHA256 = config_sha256(config)


wildcard_constraints:
    subject="|".join(SUBJECTS) if SUBJECTS else "^$",
    take="[A-Za-z0-9_-]+",


def synthetic_subjects():
    return [s for s in SUBJECTS if TAKES.loc[s, "synthetic"].all()]


def takes_of(subject):
    """Take ids of a subject (first row of a duplicate)."""
    return list(TAKES.loc[subject, "take"])


def take_row(wildcards):
    """The sheet row of a take, as a plain dict (tracked as a param)."""
    row = TAKES.loc[(wildcards.subject, wildcards.take)]
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}


def get_take_inputs(wildcards):
    """The input files of a take that exist or will be generated (a missing one is reported
    by the subject's check job, so that the DAG still builds and other subjects run)."""
    row = TAKES.loc[(wildcards.subject, wildcards.take)]
    roles = {"range": ["xyz", "color", "landmarks"], "stereo": ["left", "right", "calibration", "landmarks"]}
    files = {}
    for role in roles.get(row["modality"], []):
        path = row[role]
        if path and (row["synthetic"] or Path(path).is_file()):
            files[role] = path
    return files


def get_subject_problems(wildcards):
    return PROBLEMS.get(wildcards.subject, [])


def get_subject_parts(wildcards):
    return expand(
        "results/{subject}/takes/{take}/repair.h5",
        subject=wildcards.subject,
        take=takes_of(wildcards.subject),
    )


def get_final_outputs():
    return expand("results/{subject}/{subject}.h5", subject=SUBJECTS)
