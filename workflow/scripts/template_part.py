"""The subject's template group: faces and fiducials of the subdivided template."""

from scan2morph.jobs import run_job
from scan2morph.store import write_part
from scan2morph.template import load_template, subdivide_template
from scan2morph.template.datasets import template_datasets


def main(snakemake):
    def job():
        template = subdivide_template(
            load_template(snakemake.input.template), snakemake.params.levels
        )
        write_part(snakemake.output.part, template_datasets(template))

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
