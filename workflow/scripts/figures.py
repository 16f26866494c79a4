"""Draw every stage's figures of a subject from its store (scan2morph.render.figures)."""

import logging
from pathlib import Path

from scan2morph.jobs import run_job
from scan2morph.render.figures import write_figures


def main(snakemake):
    def job():
        stages, outputs = snakemake.params.stages, list(snakemake.output)
        timings = {}
        written = write_figures(
            snakemake.input.store, Path(outputs[0]).parent, stages, outputs, timings
        )
        for stage, seconds in timings.items():
            logging.info(
                "%s: figures of stage %s in %.2f s", snakemake.wildcards.subject, stage, seconds
            )
        logging.info("%s: %d figures", snakemake.wildcards.subject, len(written))

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
