"""Refine one take's correspondence to the neutral (the neutral's is its aligned fit)."""

from scan2morph.stages import Take, refine
from scan2morph.stages.failure import run_take_job
from scan2morph.store import read_parts, write_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        w, p, inp = snakemake.wildcards, snakemake.params, snakemake.input
        take = Take(w.subject, w.take, **p.take, data=read_parts([*inp.take, *inp.neutral]))
        params = refine.Params.from_config(snakemake.config)
        part = refine.run(load_template(inp.template), take, params)
        write_part(snakemake.output.part, part.datasets, attrs=part.attrs or None)

    w, inp = snakemake.wildcards, snakemake.input
    parts, out = [*inp.take, *inp.neutral], snakemake.output.part
    run_take_job(snakemake.log[0], job, take=w.take, stage="refine", inputs=parts, part=out)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
