"""Settle one take's landmarks (clicked or detected) and write them as an iBUG .pts file."""

from pathlib import Path

from scan2morph.io import write_pts
from scan2morph.stages import landmarks
from scan2morph.stages.failure import run_take_job
from scan2morph.stages.part import Take
from scan2morph.store import read_parts, write_part


def main(snakemake):
    def job():
        w, p, inp, out = snakemake.wildcards, snakemake.params, snakemake.input, snakemake.output
        params = landmarks.Params.from_config(snakemake.config)
        take = Take(w.subject, w.take, **p.take, data=read_parts([inp.part, *inp.neutral]))
        part = landmarks.run(None, take, params)
        write_part(out.part, part.datasets, attrs=part.attrs)
        write_pts(out.pts, part.files["pts"])

    w, inp, out = snakemake.wildcards, snakemake.input, snakemake.output
    run_take_job(
        snakemake.log[0],
        job,
        take=w.take,
        stage="landmarks",
        inputs=[inp.part, *inp.neutral],
        part=out.part,
        on_failure=lambda record: Path(out.pts).write_text(f"# no landmarks: {record}\n"),
    )


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
