"""Collect the sweep's accuracy files into results/sweeps/summary.tsv and summary.png."""

import json
from pathlib import Path

from scan2morph.jobs import run_job
from scan2morph.report.sweep import config_values, write_sweep_summary


def main(snakemake):
    def job():
        p = snakemake.params
        results = [
            (row, subject, json.loads(Path(f).read_text()))
            for (row, subject), f in zip(p.results, snakemake.input, strict=True)
        ]
        # the config's value of each swept key: the reference of the plot and the dictionary
        defaults = config_values(p.defaults, p.columns)
        out = snakemake.output
        write_sweep_summary(results, p.columns, out.table, out.plot, defaults)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
