"""Summarise every subject into results/cohort/summary.tsv and summary.png."""

import json
from pathlib import Path

from scan2morph.jobs import run_job
from scan2morph.report import write_cohort_summary


def main(snakemake):
    def job():
        inp, p, out = snakemake.input, snakemake.params, snakemake.output
        stores = dict(zip(p.subjects, inp.stores, strict=True))
        accuracies = {
            s: json.loads(Path(f).read_text())
            for s, f in zip(p.accuracy_subjects, inp.accuracy, strict=True)
        }
        write_cohort_summary(stores, accuracies, out.table, out.plot)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
