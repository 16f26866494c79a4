"""Merge a subject's parts into results/{subject}/{subject}.h5 with its warnings, checked
against the layout."""

from scan2morph.jobs import run_job
from scan2morph.stages import store
from scan2morph.store import load_layout


def main(snakemake):
    def job():
        p, inp = snakemake.params, snakemake.input
        subject = snakemake.wildcards.subject
        layout = load_layout(inp.layout)
        store.run(snakemake.output[0], inp.parts, subject, p.config_sha256, p.quality, layout)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
