"""The subject's template group: faces and fiducials of the subdivided template."""

from scan2morph.jobs import run_job
from scan2morph.stages import fit
from scan2morph.store import write_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        params = fit.Params.from_config(snakemake.config)
        part = fit.template_part(load_template(snakemake.input.template), params)
        write_part(snakemake.output.part, part.datasets)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
