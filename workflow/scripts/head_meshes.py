"""Every mesh of one subject in the head frame, for DCC tools (scan2morph.morph.head)."""

from scan2morph.jobs import run_job
from scan2morph.morph.head import write_head_meshes


def main(snakemake):
    def job():
        write_head_meshes(snakemake.input.store, snakemake.output.meshes)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
