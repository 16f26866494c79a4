"""Read one take's files into its ingest part (a stereo pair is reconstructed here)."""

from scan2morph.jobs import run_job
from scan2morph.stages import ingest
from scan2morph.store import write_part


def main(snakemake):
    def job():
        files = {role: snakemake.input[role] for role in snakemake.params.roles}
        part = ingest.run(snakemake.params.row, files, snakemake.params.stereo)
        write_part(snakemake.output.part, part.datasets, attrs=part.attrs)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
