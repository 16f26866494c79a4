"""Accuracy of a synthetic subject's outputs against its ground truth -> accuracy.json."""

from scan2morph.evaluate.subject import subject_accuracy
from scan2morph.evaluate.truth import read_truth
from scan2morph.jobs import run_job, write_json
from scan2morph.store import read_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        p = snakemake.params
        truths = {t: read_truth(f) for t, f in zip(p.takes, snakemake.input.truths, strict=True)}
        report = subject_accuracy(
            read_part(snakemake.input.store),
            truths,
            p.neutral,
            p.visemes,
            template=load_template(snakemake.input.template),
            fiducial_sets=p.fiducial_sets,
            levels=p.levels,
            smoothing=p.smoothing,
            max_slope_deg=p.max_slope_deg,
        )
        write_json(snakemake.output[0], report)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
