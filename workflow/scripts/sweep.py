"""One sweep combination on one synthetic subject: re-run the stages with the changed config
values from the subject's store and measure against the ground truth -> accuracy.json."""

from scan2morph.evaluate.truth import read_truth
from scan2morph.jobs import run_job, write_json
from scan2morph.stages import Run, Subject
from scan2morph.store import read_parts
from scan2morph.sweep import combination_accuracy, read_store
from scan2morph.template import load_template


def main(snakemake):
    def job():
        p, inp, w = snakemake.params, snakemake.input, snakemake.wildcards
        subject = Subject(f"{w.subject} ({w.params})", p.kinds, p.labels)
        run = Run(subject, load_template(inp.template), p.settings)
        truths = {t: read_truth(f) for t, f in zip(p.kinds, inp.truths, strict=True)}
        report = combination_accuracy(
            read_store(inp.store), run, truths, p.start, read_parts(inp.raw)
        )
        write_json(snakemake.output[0], report | {"sweep": dict(p.row)})

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
