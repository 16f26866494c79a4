# scan2morph: 3D face scans -> subject-specific morphable face models.
# Stages (rule files under workflow/rules/): synth, template, take (one job per take: ingest, repair, landmarks, fit,
# align, refine), subject (one job per subject: its template part, motion, motion_noise, morph, modal, store,
# head_meshes, accuracy, figures, report), cohort; sweeps (on demand: `snakemake sweep_all`).


from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


# helpers, in dependency order: the tables first, then the functions over them (no rules)
include: "workflow/rules/common.smk"
include: "workflow/rules/inputs.smk"
include: "workflow/rules/outputs.smk"
include: "workflow/rules/report_inputs.smk"
include: "workflow/rules/sweep_inputs.smk"


wildcard_constraints:
    subject="|".join(SUBJECTS) if SUBJECTS else "^$",
    take="[A-Za-z0-9_-]+",


include: "workflow/rules/synth.smk"
include: "workflow/rules/template.smk"
include: "workflow/rules/take.smk"
include: "workflow/rules/subject.smk"
include: "workflow/rules/cohort.smk"
include: "workflow/rules/sweeps.smk"


rule all:
    """Build every subject's store, figures and report, the synthetic subjects' accuracy and the cohort summary."""
    default_target: True
    input:
        get_final_outputs(),


onstart:
    drop_stale_backups()


onsuccess:
    report_left_out()


onerror:
    summarise_finished_subjects(report_left_out())
