"""Read one take's files into its ingest part (stereo reconstructed, RGB-D resampled, mesh rendered)."""

import json
from pathlib import Path

from scan2morph.errors import InputError
from scan2morph.stages import check, ingest
from scan2morph.stages.failure import run_take_job
from scan2morph.store import write_part


def main(snakemake):
    w, p, out = snakemake.wildcards, snakemake.params, snakemake.output

    def job():
        problem = check.take_problem(json.loads(Path(snakemake.input.check).read_text()), w.take)
        if problem:  # found by the subject's check job: the take is left out
            raise InputError(f"{w.subject}/{w.take}", problem)
        files = {role: snakemake.input[role] for role in p.roles}
        part = ingest.run(p.row, files, p.stereo, p.mesh_camera)
        write_part(out.part, part.datasets, attrs=part.attrs)

    run_take_job(snakemake.log[0], job, take=w.take, stage="ingest", inputs=[], part=out.part)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
