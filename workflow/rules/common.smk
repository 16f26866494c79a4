# Helpers shared by the rules: config and sheet loading, input functions, wildcard constraints.
import logging
from pathlib import Path

import pandas as pd

from snakemake.utils import validate

from scan2morph.jobs import config_sha256
from scan2morph.render.figures import STAGE_FIGURES, figure_names
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
    """Synthetic subjects grouped by which of their takes are stereo pairs, one rule each:
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
        for stage in ("template", "motion", "morph", "modal")
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
    )
