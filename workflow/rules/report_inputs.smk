# Input and params functions of the per-subject report page (report_subject, a stage of the
# subject's job: subject.smk).
from pathlib import Path

from scan2morph.render.names import FIGURE_NAMES, figure_names


def get_subject_figures(wildcards):
    """Every figure of the subject that its job's figures stage draws, in stage order."""
    return expand(
        "results/{subject}/figures/{stem}.png",
        subject=wildcards.subject,
        stem=[stem for stage in FIGURE_NAMES for stem in figure_names(stage)],
    )


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
    """Rule names in the order the workflow defines them (the stage order of the timings), a
    take job's and a subject job's stages in their place."""
    jobs = {"take": TAKE_STAGES, "subject": SUBJECT_STAGES, "subject_synthetic": ()}
    names = [r.name for r in workflow.rules]
    return [n for name in names for n in jobs.get(name, (name,))]
