"""Correspondence refinement: accuracy against the material motion, click-noise spread, timing.

Run after a pipeline run of synthetic subjects (``make run``, or any work directory):
``.venv/bin/python benchmarks/bench_refine.py --workdir . --subject synth01 [--draws 4]``.

For every take of the subject it reads the take's repair, fit and align parts, runs the refine
stage (:mod:`scan2morph.stages.refine`, the config's ``refine`` section with ``method: flow``) and
prints, for the template fit (the paper's correspondence) and for the refined one:

- the error of the raw motion (aligned take minus neutral, no mask, no smoothing) against the
  material motion of the skin (where each neutral skin point really went, from the truth), as a
  share of the material motion's RMS, and its RMS parts along the normal and along the surface
  (mm), over every vertex valid in both meshes;
- with ``--draws N``: the click-noise spread: the landmarks of the neutral and of the take are
  perturbed ``N`` times with the config's ``synthetic.scanner.click_noise_px`` (seeded), both
  refitted (and refined), and the RMS change of the motion is printed as a share of the material
  motion's RMS (the pipeline's error bar, measured the same way for both methods);
- the wall time of the refinement per take (s);
- with ``--oracle-mouth U``: the raw motion's error when the refined pixel of every vertex within
  ``U`` template units of the mouth (the mouth width is 1.12) is replaced by the true projection
  of its skin point (:func:`~scan2morph.evaluate.motion.true_positions` through the take's
  camera) and resampled as the refine stage samples: what a perfect correspondence of the mouth
  would give, the rest unchanged (both errors over the vertices that sample in both, and how
  many the oracle's pixels lose).
"""

from __future__ import annotations

import argparse
import glob
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.spatial import cKDTree

from scan2morph.align import transform_points
from scan2morph.evaluate.modality import grid_view
from scan2morph.evaluate.motion import (
    material_accuracy,
    template_lip_sides,
    true_motions,
    true_positions,
)
from scan2morph.evaluate.truth import read_truth
from scan2morph.geometry import vertex_normals
from scan2morph.stages import Take, refine
from scan2morph.stages.take_mesh import sample_points
from scan2morph.store import paths, read_parts
from scan2morph.template import fit_take, load_template, subdivide_template


def _kind(take: str, config: dict) -> str:
    kinds = {t["take"]: t["kind"] for t in config["synthetic"]["takes"]}
    return kinds[take]


@dataclass
class _Bench:
    """A subject's parts, truths and the refine stage's parameters, read once."""

    args: argparse.Namespace
    config: dict
    data: dict
    takes: list
    neutral: str
    template: object
    truths: dict
    fine: object
    params: refine.Params
    materials: dict
    skin_at: dict
    mouth: np.ndarray
    rng: np.random.Generator

    @property
    def nv(self) -> np.ndarray:
        return np.asarray(self.data[paths.mesh(self.neutral, "vertices")])


def _arguments() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=Path("."))
    ap.add_argument("--subject", default="synth01")
    ap.add_argument("--config", type=Path, default=Path("config/config.yaml"))
    ap.add_argument("--draws", type=int, default=0)
    ap.add_argument("--seed", type=int, default=2009)
    ap.add_argument("--oracle-mouth", type=float, default=None, metavar="U")
    return ap.parse_args()


def _bench(a: argparse.Namespace) -> _Bench:
    """Read the subject's parts and truths; the refine stage's parameters with ``flow``."""
    config = yaml.safe_load(a.config.read_text())
    root = a.workdir / "results" / a.subject / "takes"
    takes = sorted(p.name for p in root.iterdir() if (p / "align.h5").exists())
    neutral = next(t for t in takes if _kind(t, config) == "neutral")
    takes = [neutral] + [t for t in takes if t != neutral]
    # ingest: the camera of a stereo/RGB-D grid; landmarks: the points the fit used
    parts = ("ingest", "repair", "landmarks", "fit", "align")
    data = read_parts([root / t / f"{s}.h5" for t in takes for s in parts])
    template = load_template(a.workdir / "resources" / "template.npz")
    truth_files = {
        t: glob.glob(str(a.workdir / "results" / "**" / a.subject / "truth" / f"{t}.npz"))
        for t in takes
    }
    truths = {t: read_truth(f[0]) for t, f in truth_files.items() if f}
    fine = subdivide_template(template, int(config["template"]["subdivision_levels"]))
    params = refine.Params.from_config(config | {"refine": config["refine"] | {"method": "flow"}})
    nv = np.asarray(data[paths.mesh(neutral, "vertices")])
    others = {t: truths[t] for t in takes[1:] if t in truths}
    sides = template_lip_sides(fine.vertices)
    skin_at = (
        true_positions(nv, truths[neutral], others, sides) if a.oracle_mouth is not None else {}
    )
    mouth = cKDTree(fine.vertices[fine.mouth_boundary]).query(fine.vertices)[0]
    return _Bench(
        a,
        config,
        data,
        takes,
        neutral,
        template,
        truths,
        fine,
        params,
        true_motions(nv, truths[neutral], others, sides),
        skin_at,
        mouth <= (a.oracle_mouth or 0.0),
        np.random.default_rng(a.seed),
    )


def _refit(b: _Bench, take: str, landmarks: np.ndarray, kind: str) -> dict:
    """The take's fit with other clicks: its fit and its refined mesh (neutral frame)."""
    mesh = fit_take(
        b.template,
        landmarks,
        np.asarray(b.data[paths.range_image(take, "xyz")]),
        fiducial_set=b.params.fit.fiducial_set(kind),
        source=take,
        rules=b.params.fit.rules,
    )
    return {
        paths.mesh(take, "vertices"): mesh["vertices"],
        paths.mesh(take, "valid"): mesh["valid"],
        paths.mesh(take, "points2d"): mesh["points2d"],
        paths.landmarks(take): landmarks,
        paths.align(take, "vertices"): transform_points(
            np.asarray(b.data[paths.align(take, "transform")]), mesh["vertices"]
        ),
    }


def _header(a: argparse.Namespace) -> str:
    header = f"{'take':8s} {'material':>8s} | {'fit: rel':>9s} {'n mm':>5s} {'t mm':>5s}"
    header += f" | {'refined: rel':>12s} {'n mm':>5s} {'t mm':>5s} | {'time s':>6s}"
    if a.oracle_mouth is not None:
        header += f" | {'refined -> oracle mouth':>23s}"
    if a.draws:
        header += f" | {'click spread fit':>16s} {'refined':>7s}"
    return header


def _oracle_mouth(b: _Bench, take: str, part, ref_m, where, normals) -> str:
    """The refined motion against the same with the mouth's pixels at their true skin points."""
    view, _ = grid_view(b.truths[take], b.data, take)
    dist = np.asarray(view.extra.get("D", np.zeros(5)), dtype=np.float64)
    pos = b.skin_at[take]
    ok = np.isfinite(pos).all(axis=1)
    if view is not b.truths[take]:  # a stereo/RGB-D grid: its camera, not the take's frame
        cam = view.pose @ np.linalg.inv(b.truths[take].pose)
        pos = pos @ cam[:3, :3].T + cam[:3, 3]
    true_px = np.full((len(pos), 2), np.nan)
    true_px[ok] = cv2.projectPoints(pos[ok], np.zeros(3), np.zeros(3), view.K, dist)[0].reshape(
        -1, 2
    )
    px = np.array(part.datasets[paths.refine(take, "points2d")])
    swap = b.mouth & ok
    px[swap] = true_px[swap]
    v, v_ok = sample_points(b.data, take, px, b.fine.faces, b.params, take)
    material = b.materials[take]
    # both over the vertices the oracle's pixels sample too
    both = where & v_ok
    o = material_accuracy(v - b.nv, material, normals, both)["material_relative_error"]
    r_o = material_accuracy(ref_m, material, normals, both)["material_relative_error"]
    return f" | {r_o:8.3f} -> {o:5.3f} ({(where & ~v_ok).sum():3d} lost)"


def _click_spread(b: _Bench, take: str, kind: str, fit_m, ref_m, where, ref_rms: float) -> str:
    """The RMS change of the fit's and the refined motion over perturbed clicks."""
    click = float(b.config["synthetic"]["scanner"]["click_noise_px"])
    neutral, subject = b.neutral, b.args.subject
    sq_f, sq_r, n = 0.0, 0.0, 0
    for _ in range(b.args.draws):
        noisy = dict(b.data)
        for t, k in ((neutral, "neutral"), (take, kind)):
            lm = np.asarray(b.data[paths.landmarks(t)], dtype=np.float64)
            noisy |= _refit(b, t, lm + click * b.rng.standard_normal(lm.shape), k)
        n_take = Take(subject, neutral, "neutral", neutral, neutral, data=noisy)
        n_part = refine.run(b.template, n_take, b.params)
        t_part = refine.run(
            b.template, Take(subject, take, kind, take, neutral, data=noisy), b.params
        )
        fit_d = noisy[paths.align(take, "vertices")] - noisy[paths.align(neutral, "vertices")]
        ref_d = (
            t_part.datasets[paths.refine(take, "vertices")]
            - n_part.datasets[paths.refine(neutral, "vertices")]
        )
        d_f = np.sum((fit_d - fit_m) ** 2, axis=1)[where]
        d_r = np.sum((ref_d - ref_m) ** 2, axis=1)[where]
        ok = np.isfinite(d_f) & np.isfinite(d_r)
        sq_f, sq_r, n = sq_f + d_f[ok].sum(), sq_r + d_r[ok].sum(), n + ok.sum()
    return f" | {np.sqrt(sq_f / n) / ref_rms:16.3f} {np.sqrt(sq_r / n) / ref_rms:7.3f}"


def main() -> None:
    a = _arguments()
    b = _bench(a)
    nv, neutral = b.nv, b.neutral
    n_valid = np.asarray(b.data[paths.mesh(neutral, "valid")], dtype=bool)
    normals = vertex_normals(nv, b.fine.faces)
    print(_header(a))
    for take in b.takes[1:]:
        if take not in b.truths:
            continue
        kind = _kind(take, b.config)
        material = b.materials[take]
        t0 = time.perf_counter()
        take_in = Take(a.subject, take, kind, take, neutral, data=b.data)
        part = refine.run(b.template, take_in, b.params)
        dt = time.perf_counter() - t0
        fit_m = np.asarray(b.data[paths.align(take, "vertices")]) - nv
        ref_m = np.asarray(part.datasets[paths.refine(take, "vertices")]) - nv
        where = n_valid & np.asarray(part.datasets[paths.refine(take, "valid")])
        where &= np.asarray(b.data[paths.mesh(take, "valid")], dtype=bool)
        f = material_accuracy(fit_m, material, normals, where)
        r = material_accuracy(ref_m, material, normals, where)
        line = (
            f"{take:8s} {f['material_rms_mm']:6.2f}mm | {f['material_relative_error']:9.3f} "
            f"{f['material_normal_rms_error_mm']:5.2f} {f['material_tangential_rms_error_mm']:5.2f}"
            f" | {r['material_relative_error']:12.3f} {r['material_normal_rms_error_mm']:5.2f} "
            f"{r['material_tangential_rms_error_mm']:5.2f} | {dt:6.1f}"
        )
        if a.oracle_mouth is not None:
            line += _oracle_mouth(b, take, part, ref_m, where, normals)
        if a.draws:
            line += _click_spread(b, take, kind, fit_m, ref_m, where, f["material_rms_mm"])
        print(line, flush=True)


if __name__ == "__main__":
    main()
