"""Repair one take's range image: spikes out, small holes filled."""

from scan2morph.jobs import write_json
from scan2morph.stages import Take, repair
from scan2morph.stages.failure import run_take_job
from scan2morph.store import paths, read_attrs, read_part, write_part


def main(snakemake):
    def job():
        w, p, inp, out = snakemake.wildcards, snakemake.params, snakemake.input, snakemake.output
        attrs = read_attrs(inp.part, paths.take(w.take))
        take = Take(w.subject, w.take, **p.take, data=read_part(inp.part), attrs=attrs)
        part = repair.run(None, take, repair.Params.from_config(snakemake.config))
        write_part(out.part, part.datasets, attrs=part.attrs)
        write_json(out.report, part.files["report"])

    w, inp, out = snakemake.wildcards, snakemake.input, snakemake.output
    run_take_job(
        snakemake.log[0],
        job,
        take=w.take,
        stage="repair",
        inputs=[inp.part],
        part=out.part,
        on_failure=lambda record: write_json(out.report, {"failed": str(record)}),
    )


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
