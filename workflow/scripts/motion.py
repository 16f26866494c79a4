"""Viseme motion (mask, smoothing, models) and expression displacement fields of one subject."""

import logging

from scan2morph.jobs import run_job
from scan2morph.motion.model import AlignedMesh, expression_displacements, viseme_motion
from scan2morph.store import read_part, write_part
from scan2morph.template import load_template, subdivide_template
from scan2morph.template.regions import named_indices


def _aligned(fit_path, align_path, take):
    fit, align = read_part(fit_path), read_part(align_path)
    return AlignedMesh(align[f"/takes/{take}/align/vertices"], fit[f"/takes/{take}/mesh/valid"])


def main(snakemake):
    def job():
        p, inp, subject = snakemake.params, snakemake.input, snakemake.wildcards.subject
        template = subdivide_template(load_template(inp.template), p.levels)
        neutral = _aligned(inp.neutral_fit, inp.neutral_align, p.neutral)
        meshes = {
            t: _aligned(f, a, t) for t, f, a in zip(p.others, inp.fits, inp.aligns, strict=True)
        }
        visemes = {t: meshes[t] for t in p.visemes}
        expressions = {t: meshes[t] for t in p.expressions}
        paths = named_indices(template, p.mask["paths"], "mask.paths")
        data = viseme_motion(
            neutral,
            visemes,
            template.faces,
            paths,
            p.mask["radius_mm"],
            p.smoothing["w"],
            p.smoothing["iterations"],
            source=subject,
        )
        data |= expression_displacements(neutral, expressions, template.faces, source=subject)
        logging.info(
            "%s: %d of %d vertices suppressed",
            subject,
            data["/mask/suppressed"].sum(),
            len(data["/mask/suppressed"]),
        )
        write_part(snakemake.output.part, data)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
