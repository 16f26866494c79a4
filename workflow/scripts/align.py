"""Align one take to the neutral (identity for the neutral itself)."""

from scan2morph.stages import align
from scan2morph.stages.failure import run_take_job
from scan2morph.store import read_parts, write_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        w, p, inp = snakemake.wildcards, snakemake.params, snakemake.input
        params = align.Params.from_config(p.align, p.template)
        data = read_parts([inp.take, inp.neutral])
        template = load_template(inp.template)
        part = align.run(template, w.take, p.neutral, data, params, f"{w.subject}/{w.take}")
        write_part(snakemake.output.part, part.datasets, attrs=part.attrs or None)

    w, inp = snakemake.wildcards, snakemake.input
    parts = [inp.take, inp.neutral]
    out = snakemake.output.part
    run_take_job(snakemake.log[0], job, take=w.take, stage="align", inputs=parts, part=out)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
