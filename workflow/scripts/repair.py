"""Repair one take's range image: spikes out, small holes filled."""

from scan2morph.jobs import write_json
from scan2morph.stages import repair
from scan2morph.stages.failure import run_take_job
from scan2morph.store import paths, read_attrs, read_part, write_part


def main(snakemake):
    def job():
        w, inp, out = snakemake.wildcards, snakemake.input, snakemake.output
        attrs = read_attrs(inp.part, paths.take(w.take))
        source = f"{w.subject}/{w.take}"
        part = repair.run(w.take, read_part(inp.part), attrs, snakemake.params.repair, source)
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
