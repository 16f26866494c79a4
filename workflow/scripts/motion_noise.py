"""Click precision and the click-noise error bar of each viseme's motion (no ground truth)."""

from scan2morph.jobs import run_job
from scan2morph.stages import Subject, motion_noise
from scan2morph.store import read_part, read_parts, write_part
from scan2morph.tables import MOTION_NOISE, write_table
from scan2morph.template import load_template


def main(snakemake):
    def job():
        p, inp, out = snakemake.params, snakemake.input, snakemake.output
        subject = Subject(snakemake.wildcards.subject, p.kinds, p.labels)
        data = read_parts([*inp.repairs, *inp.aligns]) | read_part(inp.motion)
        params = motion_noise.Params.from_config(snakemake.config)
        part = motion_noise.run(load_template(inp.template), subject, data, params)
        write_part(out.part, part.datasets, attrs=part.attrs)
        write_table(out.table, part.files["table"], MOTION_NOISE)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
