"""One sweep combination on one synthetic subject: re-run the stages with the changed config
values from the subject's store and measure against the ground truth -> accuracy.json."""

from scan2morph.evaluate.truth import read_truth
from scan2morph.jobs import run_job, write_json
from scan2morph.report import rerun_accuracy
from scan2morph.store import read_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        p, inp, w = snakemake.params, snakemake.input, snakemake.wildcards
        raw = {}
        for path in inp.raw:
            raw |= read_part(path)
        truths = {t: read_truth(f) for t, f in zip(p.takes, inp.truths, strict=True)}
        report = rerun_accuracy(
            read_part(inp.store),
            p.settings,
            load_template(inp.template),
            p.kinds,
            truths,
            p.start,
            source=f"{w.subject} ({w.params})",
            raw=raw,
        )
        write_json(snakemake.output[0], report | {"sweep": dict(p.row)})

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
