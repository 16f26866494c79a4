"""Every mesh of one subject in the head frame, for DCC tools (scan2morph.io.head)."""

from scan2morph.io.head import write_head_meshes
from scan2morph.jobs import run_job


def main(snakemake):
    def job():
        write_head_meshes(snakemake.input.store, snakemake.output.meshes)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
