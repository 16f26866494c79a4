"""Merge a subject's parts into results/{subject}/{subject}.h5 and check it against the layout."""

from scan2morph.errors import InputError
from scan2morph.jobs import run_job
from scan2morph.store import load_layout, merge_parts, validate_store


def main(snakemake):
    def job():
        out = snakemake.output[0]
        merge_parts(
            out, snakemake.input.parts, snakemake.wildcards.subject, snakemake.params.config_sha256
        )
        problems = validate_store(out, load_layout(snakemake.input.layout))
        if problems:
            raise InputError(
                out, "does not match schemas/store.layout.yaml: " + "; ".join(problems)
            )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
