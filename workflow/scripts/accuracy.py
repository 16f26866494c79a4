"""Accuracy of a synthetic subject's outputs against its ground truth -> accuracy.json."""

from scan2morph.evaluate.truth import read_truth
from scan2morph.jobs import run_job, write_json
from scan2morph.stages import Subject, accuracy
from scan2morph.store import read_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        p, inp = snakemake.params, snakemake.input
        subject = Subject(snakemake.wildcards.subject, p.kinds, p.labels)
        truths = {t: read_truth(f) for t, f in zip(p.kinds, inp.truths, strict=True)}
        data = read_part(inp.store) | accuracy.truth_datasets(truths)
        params = accuracy.Params.from_config(snakemake.config)
        part = accuracy.run(load_template(inp.template), subject, data, params)
        write_json(snakemake.output[0], part.files["accuracy"])

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
