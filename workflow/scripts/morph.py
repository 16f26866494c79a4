"""PCA, blends and exports (glTF with morph targets, OBJ per model and blend) of one subject."""

from pathlib import Path

import pandas as pd

from scan2morph.io import write_glb, write_obj
from scan2morph.jobs import run_job
from scan2morph.morph import pca_tables
from scan2morph.morph.subject import pca_component_targets, pca_datasets, subject_morph
from scan2morph.store import read_part, write_part
from scan2morph.template import load_template, subdivide_template


def main(snakemake):
    def job():
        p, inp, out, subject = (
            snakemake.params,
            snakemake.input,
            snakemake.output,
            snakemake.wildcards.subject,
        )
        motion, fit, repair = (
            read_part(inp.motion),
            read_part(inp.neutral_fit),
            read_part(inp.neutral_repair),
        )
        (neutral,) = {k.split("/")[2] for k in fit}
        faces = subdivide_template(load_template(inp.template), p.levels).faces
        base = motion["/neutral/vertices"]
        models = {t: motion[f"/visemes/{t}/model"] for t in p.visemes}
        m = p.morph
        model, blends, pca_shapes = subject_morph(
            base, models, p.labels, m["blends"], m["pca_blends"], m["alpha_limit"], source=subject
        )
        data = pca_datasets(model)
        data |= {f"/blends/{k}/vertices": v for k, v in blends.items()}
        data |= {f"/pca_blends/{k}/vertices": v for k, v in pca_shapes.items()}
        write_part(out.part, data)
        eigen, coeff = pca_tables(model)
        pd.DataFrame(eigen).to_csv(out.eigen, sep="\t", index=False, float_format="%.6g")
        pd.DataFrame(coeff).to_csv(out.coefficients, sep="\t", index=False, float_format="%.6g")
        uv, texture = fit[f"/takes/{neutral}/mesh/uv"], repair[f"/takes/{neutral}/range/color"]
        write_glb(
            out.glb,
            base,
            faces,
            uv=uv,
            texture=texture,
            targets=models | pca_component_targets(model),
        )
        folder = Path(out.models)
        folder.mkdir(parents=True, exist_ok=True)
        for name, shape in {"neutral": base, **models, **blends, **pca_shapes}.items():
            write_obj(folder / f"{name}.obj", shape, faces, uv=uv, texture=texture)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
