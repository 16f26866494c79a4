"""Fit the template to one take: mesh vertices, texture coordinates, validity; OBJ export."""

from scan2morph.io import write_obj
from scan2morph.io.obj import write_failed_obj
from scan2morph.stages import Take, fit
from scan2morph.stages.failure import run_take_job
from scan2morph.store import paths, read_attrs, read_part, write_part
from scan2morph.template import load_template


def main(snakemake):
    def job():
        w, p, inp, out = snakemake.wildcards, snakemake.params, snakemake.input, snakemake.output
        attrs = read_attrs(inp.part, paths.take(w.take))
        take = Take(
            w.subject,
            w.take,
            **p.take,
            data=read_part(inp.part) | read_part(inp.landmarks),
            attrs=attrs,
        )
        part = fit.run(load_template(inp.template), take, fit.Params.from_config(snakemake.config))
        write_part(out.part, part.datasets, attrs=part.attrs)
        mesh = {k: part.datasets[paths.mesh(w.take, k)] for k in ("vertices", "uv", "valid")}
        write_obj(out.obj, faces=part.files["faces"], texture=part.files["texture"], **mesh)

    w, inp, out = snakemake.wildcards, snakemake.input, snakemake.output
    run_take_job(
        snakemake.log[0],
        job,
        take=w.take,
        stage="fit",
        inputs=[inp.part, inp.landmarks],
        part=out.part,
        on_failure=lambda record: write_failed_obj(out.obj, str(record)),
    )


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
