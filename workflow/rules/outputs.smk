# Outputs: the figure PNGs of each stage's figures rule, and the targets of rule all.
from scan2morph.render.names import FIGURE_NAMES, figure_names


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
    stems = [stem for stage in FIGURE_NAMES for stem in figure_names(stage)]
    return expand("results/{subject}/figures/{stem}.png", subject=SUBJECTS, stem=stems)


def get_final_outputs():
    return (
        expand("results/{subject}/{subject}.h5", subject=SUBJECTS)
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
