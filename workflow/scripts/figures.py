"""Draw one stage's figures of a subject from its store (scan2morph.render.figures)."""

import logging
from pathlib import Path

from scan2morph.errors import InputError
from scan2morph.jobs import run_job
from scan2morph.render.figures import write_stage_figures


def main(snakemake):
    def job():
        outputs = [Path(p) for p in snakemake.output]
        written = write_stage_figures(
            snakemake.input.store, outputs[0].parent, snakemake.params.stage
        )
        if {p.resolve() for p in written} != {p.resolve() for p in outputs}:
            raise InputError(
                "workflow/rules/figures.smk",
                f"outputs {sorted(map(str, outputs))} differ from the figures drawn {sorted(map(str, written))}",
            )
        logging.info(
            "%s: %d figures of stage %s",
            snakemake.wildcards.subject,
            len(written),
            snakemake.params.stage,
        )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
