# Outputs: every file of a subject's job (rule subject), and the targets of rule all.
from scan2morph.render.names import FIGURE_NAMES, figure_names


def figure_outputs(stage):
    """The fixed PNG outputs of one stage's figures, each a report item with its caption."""
    return {
        stem: report(
            f"results/{{subject}}/figures/{stem}.png",
            caption=f"../report/figures/{stem}.rst",
            category="Figures",
            subcategory=stage,
        )
        for stem in figure_names(stage)
    }


def subject_stage_outputs(truth):
    """The outputs of a subject's job by stage (stage -> {name: path}), report items with their
    captions; ``truth``: a synthetic subject's, with its accuracy."""
    out = {
        "template_part": {"template_part": "results/{subject}/template.h5"},
        "consensus": {"consensus": "results/{subject}/consensus.h5"},
        "motion": {"motion": "results/{subject}/motion.h5"},
        "motion_noise": {
            "motion_noise": "results/{subject}/motion_noise.h5",
            "motion_noise_table": "results/{subject}/tables/motion_noise.tsv",
        },
        "morph": {
            "morph": "results/{subject}/morph.h5",
            "eigen": report(
                "results/{subject}/tables/pca_eigenvalues.tsv",
                caption="../report/pca_eigenvalues.rst",
                category="Morphable model",
            ),
            "coefficients": report(
                "results/{subject}/tables/pca_coefficients.tsv",
                caption="../report/pca_coefficients.rst",
                category="Morphable model",
            ),
            "glb": "results/{subject}/{subject}.glb",
            "models": directory("results/{subject}/meshes/models"),
        },
        "modal": {
            "modal": "results/{subject}/modal.h5",
            "coordinates": report(
                "results/{subject}/tables/modal_coordinates.tsv",
                caption="../report/modal_coordinates.rst",
                category="Modal analysis",
            ),
            "reconstruction": report(
                "results/{subject}/tables/modal_reconstruction.tsv",
                caption="../report/modal_reconstruction.rst",
                category="Modal analysis",
            ),
            "expressions": directory("results/{subject}/meshes/expressions"),
        },
        "store": {"store": "results/{subject}/{subject}.h5"},
        "head_meshes": {"head": directory("results/{subject}/meshes/head")},
        "accuracy": {
            "accuracy": report(
                "results/{subject}/accuracy.json",
                caption="../report/accuracy.rst",
                category="Accuracy",
            )
        },
        "figures": {k: v for s in FIGURE_NAMES for k, v in figure_outputs(s).items()},
        "report_subject": {
            "report": report(
                "results/{subject}/report.html",
                caption="../report/subject_report.rst",
                category="Subject reports",
                labels={"subject": "{subject}"},
            )
        },
    }
    return {s: files for s, files in out.items() if truth or s != "accuracy"}


def subject_outputs(truth):
    """Every output of a subject's job, kept when the job starts (update: a stage that is up to
    date keeps its files), the record of its stages' fingerprints and the record of its last
    finished run (not update: deleted when the job starts, so a job that failed, its update()
    files put back with a new time, runs again)."""
    files = {
        name: update(path)
        for stage in subject_stage_outputs(truth).values()
        for name, path in stage.items()
    }
    return files | {
        "stages": update("results/{subject}/stages.json"),
        "job": "results/{subject}/job.json",
    }


def get_figure_outputs():
    """Every figure of every subject (for rule all)."""
    stems = [stem for stage in FIGURE_NAMES for stem in figure_names(stage)]
    return expand("results/{subject}/figures/{stem}.png", subject=SUBJECTS, stem=stems)


def get_final_outputs():
    return (
        expand("results/{subject}/{subject}.h5", subject=SUBJECTS)
        + expand("results/{subject}/job.json", subject=SUBJECTS)
        + expand("results/{subject}/meshes/head", subject=SUBJECTS)
        + expand("results/{subject}/accuracy.json", subject=synthetic_subjects())
        + get_figure_outputs()
        + expand("results/{subject}/report.html", subject=SUBJECTS)
        + (
            ["results/cohort/summary.tsv", "results/cohort/summary.png"]
            if SUBJECTS
            else []
        )
    )
