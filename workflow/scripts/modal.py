"""Modal basis of the neutral face and expression coordinates of one subject."""

import os

os.environ["OPENBLAS_NUM_THREADS"] = "1"  # the eigensolver's own threads run 2x faster alone
from scan2morph.jobs import run_job  # noqa: E402
from scan2morph.stages import Subject, modal  # noqa: E402
from scan2morph.store import read_part, write_part  # noqa: E402
from scan2morph.template import load_template  # noqa: E402


def main(snakemake):
    def job():
        p, inp, out = snakemake.params, snakemake.input, snakemake.output
        subject = Subject(snakemake.wildcards.subject, p.kinds, p.labels)
        params = modal.Params.from_config(snakemake.config).with_threads(snakemake.threads)
        part = modal.run(load_template(inp.template), subject, read_part(inp.motion), params)
        write_part(out.part, part.datasets, attrs=part.attrs)
        modal.write_files(part, out.coordinates, out.reconstruction, out.meshes)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
