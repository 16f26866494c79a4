"""Generate every take of one synthetic subject (range scan + color + landmarks + truth)."""

import logging

from scan2morph.jobs import run_job
from scan2morph.synth import make_take, write_take


def main(snakemake):
    def job():
        subject, p, out = snakemake.wildcards.subject, snakemake.params, snakemake.output
        for i, t in enumerate(p.takes):
            result = make_take(
                subject, t["label"], t["kind"], t["take"], seed=p.seed, params=dict(p.scanner)
            )
            write_take(result, out.xyz[i], out.color[i], out.landmarks[i], out.truth[i])
            logging.info("%s/%s: %s %s written", subject, t["take"], t["kind"], t["label"])

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
