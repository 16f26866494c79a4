"""Fail a subject whose sheet rows are broken (and only that subject), naming file and row."""

from scan2morph.errors import InputError
from scan2morph.jobs import run_job, write_json


def main(snakemake):
    def job():
        problems = list(snakemake.params.problems)
        if problems:
            raise InputError(f"subject {snakemake.wildcards.subject}", "; ".join(problems))
        write_json(snakemake.output[0], {"subject": snakemake.wildcards.subject, "problems": []})

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
