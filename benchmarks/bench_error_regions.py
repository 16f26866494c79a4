"""Where a finished run's material error lies, take by take (issue #34: what costs the mesh and
RGB-D subjects 2-4x the range subject's error).

``.venv/bin/python benchmarks/bench_error_regions.py [RUN] [--subjects synth03 synth04]
[--rings 2] [--still-mm 0.1] [--config FILE]`` reads a finished default run (``RUN``, default the repository:
``results/{subject}/{subject}.h5``, the synthetic truth ``results/synthetic/{subject}/truth`` and
the template ``resources/template.npz``) and prints, for every viseme and expression of each
synthetic subject, its material error (the error of the final motion or displacement field
against where each skin point really went, over the vertices the accuracy stage measures: a
viseme's outside the stencil mask, an expression's all) as ``accuracy.json`` gives it, and how
the squared error divides:

- ``rigid``: the share a rigid motion of the whole field removes (the best rotation and
  translation of the pipeline's moved mesh onto the true one): what the alignment costs;
- ``still``: the share on still skin (true motion below ``--still-mm``): sliding where nothing
  moved, the correspondence's own noise;
- ``rim``: the share on the forehead rim (the template's outline above the brows'
  mean height, :func:`~scan2morph.template.rim.rim_vertices`, and ``--rings`` edge rings inside
  it): where the spline extrapolates and the refinement's margin reaches hair and background;
- ``without rim`` / ``without still``: the relative error with those vertices' error set to 0.

Nothing is asserted; the printed table is the measurement. The relative error is recomputed
from the store and the truth with the accuracy stage's own functions and is printed beside
``accuracy.json``'s as a check.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.sparse as sp
import yaml

from scan2morph.evaluate.modality import take_modality
from scan2morph.evaluate.motion import material_accuracy, template_lip_sides, true_motions
from scan2morph.evaluate.truth import read_truth
from scan2morph.geometry import edge_adjacency, unique_edges, vertex_normals
from scan2morph.store import paths, read_part
from scan2morph.template import load_template, subdivide_template
from scan2morph.template.rim import rim_vertices

ROOT = Path(__file__).resolve().parents[1]


def rim_band(fine, faces: np.ndarray, rings: int) -> np.ndarray:
    """(V,) bool: the forehead rim of the subdivided template ``fine``
    (:func:`~scan2morph.template.rim.rim_vertices`: its outline above the brows' mean height)
    and ``rings`` edge rings of vertices inside it (``faces`` (F, 3) its triangles)."""
    n = len(fine.vertices)
    band = np.zeros(n, dtype=bool)
    band[rim_vertices(fine)] = True
    adjacency = edge_adjacency(unique_edges(faces), n) + sp.eye_array(n)
    for _ in range(rings):
        band = (adjacency @ band.astype(np.float64)) > 0
    return band


def rigid_share(neutral: np.ndarray, field: np.ndarray, material: np.ndarray) -> float:
    """Share of the squared error of ``field`` (V, 3) against ``material`` (V, 3) that the best
    rigid motion of the moved mesh ``neutral + field`` onto ``neutral + material`` removes."""
    p, q = neutral + field, neutral + material
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    u, _, vt = np.linalg.svd((p - pc).T @ (q - qc))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    moved = (p - pc) @ (vt.T @ d @ u.T).T + qc
    before = np.sum((p - q) ** 2)
    return float(1.0 - np.sum((moved - q) ** 2) / before) if before > 0 else 0.0


def subject_rows(run: Path, subject: str, config: dict, rings: int, still_mm: float) -> list[dict]:
    """One row per viseme and expression of ``subject`` (see the module docstring; ``config``
    the run's, for its template subdivision)."""
    store = read_part(run / "results" / subject / f"{subject}.h5")
    accuracy = json.loads((run / "results" / subject / "accuracy.json").read_text())
    truth_dir = run / "results" / "synthetic" / subject / "truth"
    v2 = np.asarray(store[paths.template("vertices2d")], dtype=np.float64)
    faces = np.asarray(store[paths.template("faces")])
    levels = int(config["template"]["subdivision_levels"])
    fine = subdivide_template(load_template(run / "resources" / "template.npz"), levels)
    rim = rim_band(fine, faces, rings)
    neutral = np.asarray(store[paths.mesh("neutral", "vertices")], dtype=np.float64)
    normals = vertex_normals(neutral, faces)
    free = ~np.asarray(store[paths.mask("suppressed")], dtype=bool)
    fields = {}
    for take, entry in accuracy["takes"].items():
        if "motion" in entry:
            fields[take] = (store[paths.viseme(take, "motion")], free, entry["motion"])
        elif "expression" in entry:
            fields[take] = (
                store[paths.expression(take, "displacement")],
                None,
                entry["expression"],
            )
    truths = {t: read_truth(truth_dir / f"{t}.npz") for t in ["neutral", *fields]}
    sides = template_lip_sides(v2)
    materials = true_motions(neutral, truths["neutral"], {t: truths[t] for t in fields}, sides)
    rows = []
    for take, (field, where, entry) in fields.items():
        field = np.asarray(field, dtype=np.float64)
        material = materials[take]
        ok = np.isfinite(field).all(axis=1) & np.isfinite(material).all(axis=1)
        ok &= np.ones(len(ok), dtype=bool) if where is None else where
        ok &= np.isfinite(neutral).all(axis=1)
        sq = np.sum((field - material) ** 2, axis=1)
        # the accuracy stage's own measure (its relative error and the motion's RMS)
        measured = material_accuracy(field, material, normals, ok)
        ref = measured["material_rms_mm"]
        still = ok & (np.linalg.norm(material, axis=1) < still_mm)
        total = sq[ok].sum()
        rows.append(
            {
                "subject": subject,
                "modality": take_modality(store, take),
                "take": take,
                "accuracy.json": entry["material_relative_error"],
                "relative": measured["material_relative_error"],
                "rigid": rigid_share(neutral[ok], field[ok], material[ok]),
                "still": sq[still].sum() / total,
                "rim": sq[ok & rim].sum() / total,
                "without rim": np.sqrt(sq[ok & ~rim].sum() / ok.sum()) / ref,
                "without still": np.sqrt(sq[ok & ~still].sum() / ok.sum()) / ref,
                "rim vertices": int((ok & rim).sum()),
            }
        )
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", nargs="?", type=Path, default=ROOT, help="a finished default run")
    ap.add_argument("--subjects", nargs="+", help="default: every synthetic subject of the run")
    ap.add_argument("--rings", type=int, default=2, help="edge rings inside the rim's outline")
    ap.add_argument("--still-mm", type=float, default=0.1, help="true motion of still skin, mm")
    ap.add_argument("--config", type=Path, help="the run's config (default RUN/config/config.yaml)")
    args = ap.parse_args(argv)
    subjects = args.subjects or sorted(
        p.name for p in (args.run / "results" / "synthetic").iterdir() if p.is_dir()
    )
    config = yaml.safe_load((args.config or args.run / "config" / "config.yaml").read_text())
    rows = [
        r for s in subjects for r in subject_rows(args.run, s, config, args.rings, args.still_mm)
    ]
    table = pd.DataFrame(rows).set_index(["subject", "modality", "take"])
    shown = ("display.width", 200, "display.max_rows", 500, "display.max_columns", 20)
    with pd.option_context(*shown):
        print(table.round(3))
        # the visemes' upper face is masked: the rim and most still skin are the expressions'
        expressions = table[table["rim vertices"] > 0]
        print("\nmeans over each subject's expressions (shares of the squared error):")
        print(expressions.groupby(level="subject").mean(numeric_only=True).round(3))


if __name__ == "__main__":
    main()
