"""Read one take's files into its ingest part (stereo reconstructed, RGB-D resampled, mesh rendered)."""

from scan2morph.jobs import run_job
from scan2morph.stages import ingest
from scan2morph.store import write_part


def main(snakemake):
    def job():
        files = {role: snakemake.input[role] for role in snakemake.params.roles}
        p = snakemake.params
        part = ingest.run(p.row, files, p.stereo, p.mesh_camera)
        write_part(snakemake.output.part, part.datasets, attrs=part.attrs)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
