"""Generate the 2D template mesh definition (resources/template.npz)."""

from scan2morph.jobs import run_job
from scan2morph.template import build_template, save_template


def main(snakemake):
    run_job(snakemake.log[0], lambda: save_template(snakemake.output[0], build_template()))


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
