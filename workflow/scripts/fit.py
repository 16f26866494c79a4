"""Fit the template to one take: mesh vertices, texture coordinates, validity; OBJ export."""

import logging

from scan2morph.io import write_obj
from scan2morph.jobs import run_job
from scan2morph.store import read_attrs, read_part, write_part
from scan2morph.template import fit_options, fit_take, load_template


def main(snakemake):
    def job():
        w, p, out = snakemake.wildcards, snakemake.params, snakemake.output
        g = f"/takes/{w.take}"
        data = read_part(snakemake.input.part)
        xyz, color = data[f"{g}/range/xyz"], data[f"{g}/range/color"]
        mesh = fit_take(
            load_template(snakemake.input.template),
            data[f"{g}/landmarks"],
            xyz,
            image_size=(xyz.shape[1], xyz.shape[0]),
            fiducial_set=p.fiducials,
            source=f"{w.subject}/{w.take}",
            **fit_options(p.template),
        )
        logging.info(
            "%s: %d vertices, %.1f%% valid, %d folded triangles",
            w.take,
            len(mesh["valid"]),
            100 * mesh["valid"].mean(),
            mesh["n_folded"],
        )
        write_part(
            out.part,
            {f"{g}/mesh/{k}": mesh[k] for k in ("vertices", "uv", "valid", "points2d")},
            attrs={
                g: read_attrs(snakemake.input.part, g)
                | {"fiducial_set": p.fiducials, "n_folded": mesh["n_folded"]}
            },
        )
        write_obj(
            out.obj,
            mesh["vertices"],
            mesh["faces"],
            uv=mesh["uv"],
            texture=color,
            valid=mesh["valid"],
        )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
