# Helpers shared by the rules: config and sheet loading, input functions, wildcard constraints.
import logging
from pathlib import Path

import pandas as pd

from snakemake.utils import validate

from scan2morph.jobs import config_sha256
from scan2morph.render.figures import STAGE_FIGURES, figure_names
from scan2morph.sheet import read_sheet, subject_problems, synthetic_rows, take_table
from scan2morph.template.mesh import FIDUCIAL_SETS

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
    config["synthetic"]["stereo"],
)
TAKES = take_table(SHEET, SYNTH)
SUBJECTS = list(dict.fromkeys(TAKES["subject"]))
PROBLEMS = subject_problems(pd.concat([SHEET, SYNTH]))
for _subject, _problems in PROBLEMS.items():
    for _problem in _problems:
        logging.getLogger("snakemake").warning(
            f"subject {_subject} will fail: {_problem}"
        )
CONFIG_SHA256 = config_sha256(config)


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
    roles = {
        "range": ["xyz", "color", "landmarks"],
        "stereo": ["left", "right", "calibration", "landmarks"],
    }
    files = {}
    for role in roles.get(row["modality"], []):
        path = row[role]
        if path and (row["synthetic"] or Path(path).is_file()):
            files[role] = path
    return files


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


def get_stereo_params(wildcards):
    """Stereo reconstruction parameters of a stereo take; {} for other takes, so that changing
    them reruns only stereo takes."""
    modality = TAKES.loc[(wildcards.subject, wildcards.take), "modality"]
    return dict(config["stereo"]) if modality == "stereo" else {}


def get_subject_problems(wildcards):
    return PROBLEMS.get(wildcards.subject, [])


def takes_of_kind(subject, kind):
    rows = TAKES.loc[subject]
    return list(rows.loc[rows["kind"] == kind, "take"])


def get_neutral_take(wildcards):
    neutral = takes_of_kind(wildcards.subject, "neutral")
    return neutral[0] if neutral else ""


def get_viseme_takes(wildcards):
    return takes_of_kind(wildcards.subject, "viseme")


def get_expression_takes(wildcards):
    return takes_of_kind(wildcards.subject, "expression")


def get_other_takes(wildcards):
    """Visemes then expressions (the order the motion script zips with its inputs)."""
    return get_viseme_takes(wildcards) + get_expression_takes(wildcards)


def _take_files(pattern, subject, takes):
    return expand(pattern, subject=subject, take=takes)


def get_neutral_fit(wildcards):
    take = get_neutral_take(wildcards)
    return f"results/{wildcards.subject}/takes/{take}/fit.h5" if take else []


def get_neutral_align(wildcards):
    take = get_neutral_take(wildcards)
    return f"results/{wildcards.subject}/takes/{take}/align.h5" if take else []


def get_other_fits(wildcards):
    return _take_files(
        "results/{subject}/takes/{take}/fit.h5",
        wildcards.subject,
        get_other_takes(wildcards),
    )


def get_other_aligns(wildcards):
    return _take_files(
        "results/{subject}/takes/{take}/align.h5",
        wildcards.subject,
        get_other_takes(wildcards),
    )


def get_viseme_repairs(wildcards):
    return _take_files(
        "results/{subject}/takes/{take}/repair.h5",
        wildcards.subject,
        get_viseme_takes(wildcards),
    )


def get_viseme_aligns(wildcards):
    return _take_files(
        "results/{subject}/takes/{take}/align.h5",
        wildcards.subject,
        get_viseme_takes(wildcards),
    )


def get_neutral_repair(wildcards):
    take = get_neutral_take(wildcards)
    return f"results/{wildcards.subject}/takes/{take}/repair.h5" if take else []


def get_take_labels(wildcards):
    rows = TAKES.loc[wildcards.subject]
    return dict(zip(rows["take"], rows["label"]))


def get_fiducial_sets(wildcards):
    """Fiducial set of every take of a subject (take -> set name)."""
    rows = TAKES.loc[wildcards.subject]
    sets = config["template"]["fiducials"]
    return {t: sets.get(k, "closed") for t, k in zip(rows["take"], rows["kind"])}


def get_fiducial_set(wildcards):
    kind = TAKES.loc[(wildcards.subject, wildcards.take), "kind"]
    return config["template"]["fiducials"].get(kind, "closed")


def get_subject_parts(wildcards):
    """Every part merged into the subject's store."""
    takes = takes_of(wildcards.subject)
    per_take = [
        _take_files(
            f"results/{{subject}}/takes/{{take}}/{stage}.h5", wildcards.subject, takes
        )
        for stage in ("repair", "fit", "align")
    ]
    per_subject = [
        f"results/{wildcards.subject}/{stage}.h5"
        for stage in ("template", "motion", "motion_noise", "morph", "modal")
    ]
    return sum(per_take, []) + per_subject


def get_takes(wildcards):
    return takes_of(wildcards.subject)


def get_truth_files(wildcards):
    return expand(
        f"{SYNTH_ROOT}/{{subject}}/truth/{{take}}.npz",
        subject=wildcards.subject,
        take=takes_of(wildcards.subject),
    )


def figure_outputs(stage):
    """The fixed PNG outputs of one stage's figures rule, each a report item with its caption."""
    return {
        stem: report(
            f"results/{{subject}}/figures/{stem}.png",
            caption=f"../report/figures/{stem}.rst",
            category="Figures",
            subcategory=stage,
        )
        for stem in figure_names(stage)
    }


def get_figure_outputs():
    """Every figure of every subject (for rule all)."""
    stems = [stem for stage in STAGE_FIGURES for stem in figure_names(stage)]
    return expand("results/{subject}/figures/{stem}.png", subject=SUBJECTS, stem=stems)


def get_final_outputs():
    return (
        expand("results/{subject}/{subject}.h5", subject=SUBJECTS)
        + expand("results/{subject}/accuracy.json", subject=synthetic_subjects())
        + get_figure_outputs()
        + expand("results/{subject}/report.html", subject=SUBJECTS)
        + (
            ["results/cohort/summary.tsv", "results/cohort/summary.png"]
            if SUBJECTS
            else []
        )
    )


# --- helpers of report.smk ---
from glob import glob

from scan2morph.render.figures import STAGE_FIGURES, figure_names


# Input helpers (used by this file only).
def get_subject_figures(wildcards):
    """Every figure of the subject that the figures rules draw (a stage whose rule is not in the
    workflow contributes the PNGs already in the figures folder)."""
    files = []
    for stage in STAGE_FIGURES:
        if rules.has(f"figures_{stage}"):
            files += expand(
                "results/{subject}/figures/{stem}.png",
                subject=wildcards.subject,
                stem=figure_names(stage),
            )
        else:
            files += sorted(glob(f"results/{wildcards.subject}/figures/{stage}_*.png"))
    return files


def get_figure_captions(wildcards):
    """The caption file of each figure that has one (workflow/report/figures/{stem}.rst)."""
    folder = Path(workflow.basedir) / "workflow" / "report" / "figures"
    stems = [Path(f).stem for f in get_subject_figures(wildcards)]
    return [str(folder / f"{s}.rst") for s in stems if (folder / f"{s}.rst").is_file()]


def get_subject_accuracy(wildcards):
    """The subject's accuracy.json (synthetic subjects), else nothing."""
    if wildcards.subject in synthetic_subjects():
        return [f"results/{wildcards.subject}/accuracy.json"]
    return []


def get_rule_order(wildcards):
    """Rule names in the order the workflow defines them (the stage order of the timings)."""
    return [r.name for r in workflow.rules]


# --- helpers of sweeps.smk ---
import re
from pathlib import Path

import pandas as pd

from snakemake.utils import Paramspace

from scan2morph.errors import InputError
from scan2morph.report.sweep import read_sweep_table, sweep_settings

SWEEP_TABLE = (
    read_sweep_table(
        config["sweeps"], Path(workflow.basedir) / "schemas" / "config.schema.yaml"
    )
    if Path(config["sweeps"]).is_file()
    else None
)
# one folder per combination, results/sweeps/{column}~{value}/.../ (Paramspace instance patterns)
SWEEP_SPACE = Paramspace(
    SWEEP_TABLE.frame() if SWEEP_TABLE else pd.DataFrame(), single_wildcard="params"
)
# folder of a combination -> its values by dotted config path
SWEEP_ROWS = dict(
    zip(SWEEP_SPACE.instance_patterns, SWEEP_TABLE.rows if SWEEP_TABLE else ())
)


# Input helpers (used by this file only).
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


def get_take_kinds(wildcards):
    rows = TAKES.loc[wildcards.subject]
    return dict(zip(rows["take"], rows["kind"]))


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
