"""Draw one stage's figures of a subject from its store (scan2morph.render.figures)."""

import logging
from pathlib import Path

from scan2morph.jobs import run_job
from scan2morph.render.figures import write_stage_figures


def main(snakemake):
    def job():
        stage, outputs = snakemake.params.stage, list(snakemake.output)
        written = write_stage_figures(
            snakemake.input.store, Path(outputs[0]).parent, stage, outputs
        )
        logging.info("%s: %d figures of stage %s", snakemake.wildcards.subject, len(written), stage)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
