# The parameter sweep table and the input and params functions of the sweep rules (sweeps.smk).
# The table is read and checked against the config schema here, when the workflow loads.
from pathlib import Path

import pandas as pd

from snakemake.utils import Paramspace

from scan2morph.errors import InputError
from scan2morph.sweep import check_sweep_rows, read_sweep_table, sweep_settings

try:  # a bad table stops the run as a bad config does: one line, no traceback
    SWEEP_TABLE = (
        read_sweep_table(
            config["sweeps"], Path(workflow.basedir) / "schemas" / "config.schema.yaml"
        )
        if Path(config["sweeps"]).is_file()
        else None
    )
    # each combination's settings as a config's (one against another), once a run
    if SWEEP_TABLE is not None and workflow.is_main_process:
        check_sweep_rows(SWEEP_TABLE, config)
except InputError as exc:
    stop_run(exc)
# one folder per combination, results/sweeps/{column}~{value}/.../ (Paramspace instance patterns)
SWEEP_SPACE = Paramspace(
    SWEEP_TABLE.frame() if SWEEP_TABLE else pd.DataFrame(), single_wildcard="params"
)
# folder of a combination -> its values by dotted config path
SWEEP_ROWS = dict(
    zip(SWEEP_SPACE.instance_patterns, SWEEP_TABLE.rows if SWEEP_TABLE else ())
)


def get_sweep_raw(wildcards):
    """The subject's ingest parts (raw range images) when a sweep re-runs the repair stage."""
    if SWEEP_TABLE is None or SWEEP_TABLE.first_stage != "repair":
        return []
    return expand(
        "results/{subject}/takes/{take}/ingest.h5",
        subject=wildcards.subject,
        take=takes_of(wildcards.subject),
    )


def get_sweep_settings(wildcards):
    """The config sections the re-run stages read, with the combination's values set."""
    return sweep_settings(config, SWEEP_ROWS[wildcards.params])


def get_sweep_row(wildcards):
    return dict(SWEEP_ROWS[wildcards.params])


def get_sweep_results(wildcards):
    """Every combination's accuracy of every synthetic subject (a clear error if none)."""
    if not SWEEP_ROWS:
        raise InputError(
            f"{config['sweeps']} (config key 'sweeps')",
            "no parameter sweep: the sweep table is missing or has no rows",
        )
    if not synthetic_subjects():
        raise InputError(
            "config key 'synthetic.subjects'",
            "a parameter sweep runs on the synthetic cohort: set it above 0",
        )
    return expand(
        "results/sweeps/{params}/{subject}/accuracy.json",
        params=SWEEP_SPACE.instance_patterns,
        subject=synthetic_subjects(),
    )


def get_sweep_result_rows(wildcards):
    """(combination, subject) of each input of sweep_summary, in input order."""
    return [
        [dict(row), subject]
        for row in SWEEP_ROWS.values()
        for subject in synthetic_subjects()
    ]
