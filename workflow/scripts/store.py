"""Merge a subject's parts into results/{subject}/{subject}.h5 with its warnings, checked
against the layout."""

from scan2morph.jobs import run_job
from scan2morph.stages import Subject, store
from scan2morph.store import load_layout
from scan2morph.store.hdf5 import write_file


def main(snakemake):
    def job():
        p, inp = snakemake.params, snakemake.input
        subject = Subject(snakemake.wildcards.subject, p.kinds, p.labels)
        params = store.Params.from_config(snakemake.config).with_layout(load_layout(inp.layout))
        part = store.run(None, subject, {"parts": list(inp.parts)}, params)
        write_file(snakemake.output[0], part.files["store"])

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
