"""Modal basis of the neutral face, expression coordinates and statistics of one subject."""

import os

# One BLAS thread: the eigensolver runs its own threads, and spinning BLAS threads slow it ~2x.
os.environ["OPENBLAS_NUM_THREADS"] = "1"

import logging  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from scan2morph.io import write_obj  # noqa: E402
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
        # The paper fixes the face's outline; the mouth loop (the lips) stays free.
        outline = np.zeros(template.n_vertices, dtype=bool)
        outline[template.boundary] = True
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
            fixed=outline,
        )
        logging.info(
            "%s: %d modes, %.1f to %.1f Hz", subject, basis.n_modes, *basis.frequencies_hz[[0, -1]]
        )
        write_part(snakemake.output.part, data)
        out = snakemake.output
        coords = {t: data[f"/expressions/{t}/coordinates"] for t in p.expressions}
        columns = [f"q{i + 1}" for i in range(basis.n_modes)]
        pd.DataFrame.from_dict(coords, orient="index", columns=columns).rename_axis("take").to_csv(
            out.coordinates, sep="\t", float_format="%.6g"
        )
        ks = data["/modal/reconstruction_k"]
        errors = {t: data[f"/expressions/{t}/reconstruction_rms_mm"] for t in p.expressions}
        pd.DataFrame.from_dict(errors, orient="index", columns=[f"K={k}" for k in ks]).rename_axis(
            "take"
        ).to_csv(out.reconstruction, sep="\t", float_format="%.4f")
        # Each expression as measured and as synthesised back from its k coordinates (Fig. 8).
        folder = Path(out.meshes)
        folder.mkdir(parents=True, exist_ok=True)
        base = motion["/neutral/vertices"]
        for t in p.expressions:
            write_obj(folder / f"{t}_measured.obj", base + fields[t], template.faces)
            write_obj(
                folder / f"{t}_synthesized.obj",
                base + data[f"/expressions/{t}/synthesized"],
                template.faces,
            )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
