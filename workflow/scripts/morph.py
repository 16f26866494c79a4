"""PCA, blends and exports (glTF with morph targets, OBJ per model and blend) of one subject."""

from scan2morph.jobs import run_job
from scan2morph.stages import Subject, morph
from scan2morph.store import read_parts, write_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        p, inp, out = snakemake.params, snakemake.input, snakemake.output
        subject = Subject(snakemake.wildcards.subject, p.kinds, p.labels)
        data = read_parts([inp.motion, inp.neutral_fit, inp.neutral_repair])
        params = morph.Params.from_config(snakemake.config)
        part = morph.run(load_template(inp.template), subject, data, params)
        write_part(out.part, part.datasets, attrs=part.attrs)
        morph.write_files(part, out.eigen, out.coefficients, out.glb, out.models)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
