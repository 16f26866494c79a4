"""Align one take to the neutral (identity for the neutral itself)."""

import logging

import numpy as np

from scan2morph.align import align_take, transform_points
from scan2morph.jobs import run_job
from scan2morph.store import read_part, write_part
from scan2morph.template import load_template, subdivide_template
from scan2morph.template.regions import icp_region, named_indices


def main(snakemake):
    def job():
        w, p = snakemake.wildcards, snakemake.params
        take, neutral = read_part(snakemake.input.take), read_part(snakemake.input.neutral)
        (key_t,) = {k.split("/")[2] for k in take}
        (key_n,) = {k.split("/")[2] for k in neutral}
        src, src_valid = take[f"/takes/{key_t}/mesh/vertices"], take[f"/takes/{key_t}/mesh/valid"]
        g = f"/takes/{w.take}/align"
        attrs = {}
        if key_t == key_n:
            transform = np.eye(4)
        else:
            template = subdivide_template(load_template(snakemake.input.template), p.levels)
            settings = {k: v for k, v in p.align.items() if k not in ("point_pairs", "icp_region")}
            result = align_take(
                src,
                src_valid,
                neutral[f"/takes/{key_n}/mesh/vertices"],
                neutral[f"/takes/{key_n}/mesh/valid"],
                template.faces,
                named_indices(template, p.align["point_pairs"], "align.point_pairs"),
                np.flatnonzero(icp_region(template, p.align["icp_region"])),
                settings,
                source=f"{w.subject}/{w.take}",
            )
            transform = result.transform
            attrs = dict(
                fitness=result.fitness,
                inlier_rmse_mm=result.inlier_rmse,
                iterations=result.iterations,
                converged=result.converged,
                method=result.method,
            )
            logging.info("%s: %s", w.take, attrs)
        write_part(
            snakemake.output.part,
            {f"{g}/transform": transform, f"{g}/vertices": transform_points(transform, src)},
            attrs={g: attrs} if attrs else None,
        )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
