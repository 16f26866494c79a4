"""Modal basis of the neutral face, expression coordinates and statistics of one subject."""

import os

# One BLAS thread: the eigensolver runs its own threads, and spinning BLAS threads slow it ~2x.
os.environ["OPENBLAS_NUM_THREADS"] = "1"

import logging  # noqa: E402

from scan2morph.jobs import run_job  # noqa: E402
from scan2morph.modal import ModalParams, ShellMaterial  # noqa: E402
from scan2morph.modal.subject import subject_modal  # noqa: E402
from scan2morph.store import read_part, write_part  # noqa: E402
from scan2morph.template import load_template, subdivide_template  # noqa: E402
from scan2morph.template.regions import upper_face  # noqa: E402


def main(snakemake):
    def job():
        p, inp, subject = snakemake.params, snakemake.input, snakemake.wildcards.subject
        m = p.modal
        template = subdivide_template(load_template(inp.template), p.levels)
        motion = read_part(inp.motion)
        params = ModalParams(
            n_modes=m["modes"],
            thickness_mm=m["thickness_mm"],
            upper_thickness_factor=m["stiff_factor"],
            material=ShellMaterial(
                m["youngs_modulus_mpa"], m["poisson_ratio"], m["density_t_per_mm3"]
            ),
            threads=snakemake.threads,
            seed=m["seed"],
        )
        fields = {t: motion[f"/expressions/{t}/displacement"] for t in p.expressions}
        semantic = [
            next(t for t in p.expressions if p.labels[t] == lab)
            for lab in m["semantic_labels"]
            if any(p.labels[t] == lab for t in p.expressions)
        ]
        basis, data = subject_modal(
            motion["/neutral/vertices"],
            template.faces,
            upper_face(template, m["stiff_above"]),
            params,
            fields,
            p.labels,
            semantic,
            m["reconstruction_k"],
            source=subject,
        )
        logging.info(
            "%s: %d modes, %.1f to %.1f Hz", subject, basis.n_modes, *basis.frequencies_hz[[0, -1]]
        )
        write_part(snakemake.output.part, data)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
