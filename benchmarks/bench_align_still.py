"""Why a take's alignment is off: its still skin, noise and an oracle, from a finished run.

For every take of the given synthetic subjects, the take is aligned again from the run's fit
parts (``results/{subject}/takes/{take}/fit.h5``) as the align stage does, and its rotation
error against the truth is printed beside what the truth says about the alignment's data:

``still``
    Candidate vertices (the ICP region and the skin it may grow into) whose true motion is below
    0.05 mm (the truth's displacement at the vertex's closest point on the take's true surface).
``rms@truth``
    Robust RMS (from the median square) point-to-plane residual of those vertices at the *true*
    pose, mm: what a right alignment leaves, against ``expected`` (the RMSE the meshes' measured roughness predicts) and
    ``resid`` (the kept region's RMSE at the estimated pose).
``fit err``, ``corr``
    RMS normal distance of the take's fitted upper-face vertices to its true surface, mm, and the
    correlation of that error between vertices less than 4 mm apart (neighbours): the roughness
    noise estimate assumes it is 0.
``kept mov``
    Vertices the alignment kept whose true motion is above 0.2 mm, of all it kept.
``oracle``, ``oracle 3s``
    Rotation error of the same ICP run on the truly still vertices only (from the true pose),
    with the pipeline's kernel and with a kernel of 3 x ``rms@truth``, degrees.
``rot``
    The alignment's rotation error, degrees.

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/bench_align_still.py --run RUN [--config F] synth04

``--run`` is a folder holding ``results/`` and ``resources/template.npz`` of a finished default
run (default: this checkout).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial import cKDTree

from scan2morph.align import AlignMeshes, align_take, rotation_angle_deg, transform_points
from scan2morph.align.icp import _icp_problem, _refine_icp, _vertex_sets
from scan2morph.align.noise import robust_rms
from scan2morph.evaluate.mesh import alignment_accuracy, true_alignment
from scan2morph.evaluate.truth import closest_points, read_truth
from scan2morph.geometry import vertex_normals
from scan2morph.stages import align
from scan2morph.store import paths, read_parts
from scan2morph.template import load_template, subdivide_template
from scan2morph.template.regions import icp_region, named_indices

#: True motion below this is still skin, above ``MOVING_MM`` moving, mm.
STILL_MM = 0.05
MOVING_MM = 0.2
#: Vertices closer than this are neighbours for the error's correlation, mm.
NEIGHBOUR_MM = 4.0


def _fit_error(v: np.ndarray, idx: np.ndarray, truth, faces) -> tuple[float, float]:
    """RMS normal error of vertices ``idx`` against the true surface, mm, and its correlation
    between neighbours."""
    face, bary, _ = closest_points(truth.posed_vertices(), truth.faces, v[idx])
    on = np.einsum("qk,qkd->qd", bary, truth.posed_vertices()[truth.faces[face]])
    e = np.einsum("ij,ij->i", v[idx] - on, vertex_normals(v, faces)[idx])
    ok = np.isfinite(e)
    e, x = e[ok] - np.median(e[ok]), v[idx][ok]
    pairs = cKDTree(x).query_pairs(NEIGHBOUR_MM, output_type="ndarray")
    corr = float(np.mean(e[pairs[:, 0]] * e[pairs[:, 1]]) / np.mean(e**2))
    return float(np.sqrt(np.mean(e**2))), corr


def take_row(data: dict, take: str, truths: tuple, fine, prm: align.Params) -> dict:
    """The diagnosis of one take (see the module docstring for the keys)."""
    tt, tn = truths
    src, sv = data[paths.mesh(take, "vertices")], data[paths.mesh(take, "valid")]
    dst, dv = data[paths.mesh("neutral", "vertices")], data[paths.mesh("neutral", "valid")]
    pairs = named_indices(fine, prm.point_pairs, "align.point_pairs")
    region = np.flatnonzero(icp_region(fine, prm.icp_region))
    grow = align.grow_indices(fine, prm.grow_into)
    res = align_take(AlignMeshes(src, sv, dst, dv, fine.faces), pairs, region, prm.icp, take, grow)
    acc = alignment_accuracy(res.transform, src, sv, tt, tn)
    _, upper, cand = _vertex_sets(len(src), pairs, region, grow, take)
    s = _icp_problem((src, sv), (dst, dv, fine.faces), upper, cand, "icp", take)
    face, bary, _ = closest_points(tt.posed_vertices(), tt.faces, s.p)
    motion = np.linalg.norm(np.einsum("qk,qkd->qd", bary, tt.displacement[tt.faces[face]]), axis=1)
    true = true_alignment(tt, tn)
    still = motion < STILL_MM
    rms = robust_rms(s.plane(transform_points(true, s.p[still])))
    kept = np.isin(s.p_idx, res.kept_indices)
    oracle = []
    for k in (res.kernel_k, 3.0 * rms):
        t, *_ = _refine_icp(s.p[still], s.q, s.q_normals, true, replace(prm.icp, kernel_k_mm=k))
        oracle.append(rotation_angle_deg(t[:3, :3].T @ true[:3, :3]))
    fit_rms, corr = _fit_error(src, np.flatnonzero(cand & sv), tt, fine.faces)
    return {
        "rot": acc["rotation_deg"],
        "still": int(still.sum()),
        "cand": len(s.p),
        "rms_truth": rms,
        "expected": res.expected_rmse,
        "resid": res.residual_rmse,
        "fit": fit_rms,
        "corr": corr,
        "kept_moving": f"{int((kept & (motion > MOVING_MM)).sum())}/{int(kept.sum())}",
        "oracle": oracle[0],
        "oracle3s": oracle[1],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("subjects", nargs="+")
    ap.add_argument("--run", type=Path, default=Path(__file__).parents[1])
    ap.add_argument("--config", type=Path, default=Path(__file__).parents[1] / "config/config.yaml")
    args = ap.parse_args()
    prm = align.Params.from_config(yaml.safe_load(args.config.read_text()))
    fine = subdivide_template(load_template(args.run / "resources/template.npz"), prm.levels)
    results = args.run / "results"
    print(
        f"{'subject':8} {'take':7} {'rot':>6} {'still':>9} {'rms@truth':>9} {'expected':>8} "
        f"{'resid':>6} {'fit err':>7} {'corr':>5} {'kept mov':>8} {'oracle':>6} {'oracle 3s':>9}"
    )
    for subject in args.subjects:
        takes = json.loads((results / subject / "accuracy.json").read_text())["takes"]
        tn = read_truth(results / "synthetic" / subject / "truth" / "neutral.npz")
        for take in [t for t in takes if t != "neutral"]:
            data = read_parts(
                [results / subject / "takes" / t / "fit.h5" for t in (take, "neutral")]
            )
            tt = read_truth(results / "synthetic" / subject / "truth" / f"{take}.npz")
            r = take_row(data, take, (tt, tn), fine, prm)
            print(
                f"{subject:8} {take:7} {r['rot']:6.3f} {r['still']:4d}/{r['cand']:4d} "
                f"{r['rms_truth']:9.3f} {r['expected']:8.3f} {r['resid']:6.3f} {r['fit']:7.3f} "
                f"{r['corr']:5.2f} {r['kept_moving']:>8} {r['oracle']:6.3f} {r['oracle3s']:9.3f}"
            )


if __name__ == "__main__":
    main()
