"""Read one take's files into its ingest part (stereo reconstructed, RGB-D resampled, mesh rendered)."""

import json
from pathlib import Path

from scan2morph.errors import InputError
from scan2morph.sheet import PATH_SEPARATOR
from scan2morph.stages import Take, check, ingest
from scan2morph.stages.failure import run_take_job
from scan2morph.store import write_part


def _value(files):
    """One input's file, or several (an RGB-D take's depth frames) joined as in the sheet."""
    return files if isinstance(files, str) else PATH_SEPARATOR.join(files)


def main(snakemake):
    w, p, out = snakemake.wildcards, snakemake.params, snakemake.output

    def job():
        problem = check.take_problem(json.loads(Path(snakemake.input.check).read_text()), w.take)
        if problem:  # found by the subject's check job: the take is left out
            raise InputError(f"{w.subject}/{w.take}", problem)
        files = {role: _value(snakemake.input[role]) for role in p.roles}
        take = Take.from_row(p.row, files=files)
        part = ingest.run(None, take, ingest.Params.from_config(snakemake.config))
        write_part(out.part, part.datasets, attrs=part.attrs)

    run_take_job(snakemake.log[0], job, take=w.take, stage="ingest", inputs=[], part=out.part)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
