"""Viseme motion (mask, smoothing, models) and expression displacement fields of one subject."""

from scan2morph.jobs import run_job
from scan2morph.stages import Subject, motion
from scan2morph.store import read_parts, write_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        p, inp = snakemake.params, snakemake.input
        subject = Subject(snakemake.wildcards.subject, p.kinds, p.labels)
        params = motion.Params.from_config(snakemake.config)
        data = read_parts([*inp.fits, *inp.aligns, *inp.refines])
        part = motion.run(load_template(inp.template), subject, data, params)
        write_part(snakemake.output.part, part.datasets)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
