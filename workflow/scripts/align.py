"""Align one take to the neutral (identity for the neutral itself)."""

from scan2morph.stages import Take, align
from scan2morph.stages.failure import run_take_job
from scan2morph.store import read_parts, write_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        w, p, inp = snakemake.wildcards, snakemake.params, snakemake.input
        take = Take(w.subject, w.take, **p.take, data=read_parts([inp.take, inp.neutral]))
        params = align.Params.from_config(snakemake.config)
        part = align.run(load_template(inp.template), take, params)
        write_part(snakemake.output.part, part.datasets, attrs=part.attrs or None)

    w, inp = snakemake.wildcards, snakemake.input
    parts = [inp.take, inp.neutral]
    out = snakemake.output.part
    run_take_job(snakemake.log[0], job, take=w.take, stage="align", inputs=parts, part=out)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
