"""Collect the sweep's accuracy files into results/sweeps/summary.tsv and summary.png."""

import json
from pathlib import Path

from scan2morph.jobs import run_job
from scan2morph.report import write_sweep_summary


def main(snakemake):
    def job():
        p = snakemake.params
        results = [
            (row, subject, json.loads(Path(f).read_text()))
            for (row, subject), f in zip(p.results, snakemake.input, strict=True)
        ]
        write_sweep_summary(results, p.columns, snakemake.output.table, snakemake.output.plot)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
