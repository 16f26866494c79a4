"""Take-to-neutral alignment: accuracy on the synthetic cohort, and timing.

Run: ``.venv/bin/python benchmarks/bench_align.py [--subjects N] [--config config/config.yaml]``.
Simulates the subjects' takes in memory as the pipeline does (range takes: ``make_take`` with the
config's ``synthetic.scanner``; the stereo takes ``synthetic.stereo`` lists: ``make_stereo_take``
with its rig and ``reconstruct_stereo`` with the config's ``stereo``; then ``repair_range`` and
``fit_take`` with the config's template options and fiducial set per kind; subjects of other
modalities are skipped), aligns every take to its subject's neutral as the align stage does
(``align.point_pairs`` for the initial pose, ICP on ``align.icp_region`` grown into the still
skin of ``align.grow_into``, the rest of ``align`` as :func:`~scan2morph.align.align_take`'s
settings) and prints per take the rotation (deg) and
translation (mm, at the face centroid) error against the truth (as the accuracy report computes
them), ICP's fitness, the point-to-plane RMSE of the kept region (mm), the measured noise of the
take's and the neutral's region (mm), the RMSE limit used (mm; ``*`` absolute), the share of the
region kept, iterations, convergence and the verdict.

The code before a change: ``PYTHONPATH=/tmp/base/src .venv/bin/python benchmarks/bench_align.py
--config /tmp/base/config/config.yaml`` (an older library lacks the verdict: ``-``).

``--timing``: the median wall time in ms of ``align_take`` (both refinements) and
``laplacian_smooth`` (w = 0.1, 30 iterations, with a suppressed mask and a few missing
vertices) on a face-like grid at 1.7k and 7k vertices, and the alignment error against the
known motion.
"""

from __future__ import annotations

import argparse
import time
from functools import partial
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from scan2morph.align import (
    AlignMeshes,
    IcpParams,
    align_take,
    invert,
    rotation_angle_deg,
    transform_points,
)
from scan2morph.motion import laplacian_smooth


def _grid_faces(nx: int, ny: int) -> np.ndarray:
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _face(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """Face-like height field, 160 x 200 mm."""
    x, y = np.meshgrid(np.linspace(-80, 80, nx), np.linspace(-100, 100, ny))

    def g(cx, cy, sx, sy=None):
        sy = sx if sy is None else sy
        return np.exp(-((x - cx) ** 2 / (2 * sx * sx) + (y - cy) ** 2 / (2 * sy * sy)))

    z = (
        60 * g(0, 0, 70)
        + 25 * g(0, 5, 10, 18)
        - 10 * g(-32, 30, 12)
        - 10 * g(32, 30, 12)
        + 10 * g(0, -80, 20)
        + 7 * g(0, 48, 35, 6)
        + 9 * g(-45, -5, 12)
        + 9 * g(45, -5, 12)
    )
    return np.stack([x.ravel(), y.ravel(), z.ravel()], 1), _grid_faces(nx, ny)


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def timing(seed: int = 0, repeats: int = 7) -> None:
    """Median time of ``align_take`` and ``laplacian_smooth`` on a face-like grid."""
    rng = np.random.default_rng(seed)
    print(f"{'V':>6} {'method':>16} {'align ms':>9} {'rot err deg':>12} {'t err mm':>9}")
    for nx, ny in ((37, 46), (75, 94)):
        v, f = _face(nx, ny)
        r_mouth = np.hypot(v[:, 0], v[:, 1] + 45)
        bump = np.where(r_mouth < 30, np.cos(np.pi / 2 * r_mouth / 30) ** 2, 0.0)
        upper = np.flatnonzero((v[:, 1] > -15) & (r_mouth > 40))
        pairs = np.array(
            [
                np.argmin(np.linalg.norm(v[:, :2] - p, axis=1))
                for p in [(-50, 40), (50, 40), (0, 30), (-60, 0), (60, 0), (0, 80)]
            ]
        )
        truth = np.eye(4)
        truth[:3, :3] = Rotation.from_rotvec(np.radians(5) * np.array([0.6, 0.0, 0.8])).as_matrix()
        truth[:3, 3] = [6.0, -8.0, 0.0]
        viseme = v + 10.0 * bump[:, None] * np.array([0.0, -1.0, 0.3])
        take = transform_points(invert(truth), viseme) + rng.normal(scale=0.1, size=v.shape)
        take[pairs] += rng.normal(scale=1.0, size=(6, 3))
        valid = np.ones(len(v), dtype=bool)
        centre = v[upper].mean(axis=0)
        for method in ("icp", "correspondence"):
            args = (AlignMeshes(take, valid, v, valid, f), pairs, upper, IcpParams(method=method))
            run = partial(align_take, *args, source="bench/take")
            run()  # warm-up (open3d import)
            ms = _median_ms(run, repeats)
            err = run().transform @ invert(truth)
            rot = rotation_angle_deg(err)
            t_err = np.linalg.norm(transform_points(err, centre) - centre)
            print(f"{len(v):>6} {method:>16} {ms:>9.2f} {rot:>12.4f} {t_err:>9.4f}")

        d = rng.normal(size=(len(v), 3))
        fixed = v[:, 1] > 0
        missing = rng.random(len(v)) < 0.02
        ms = _median_ms(partial(laplacian_smooth, d, f, 0.1, 30, fixed, missing), repeats)
        print(f"{len(v):>6} {'laplacian_smooth':>16} {ms:>9.2f}   (w=0.1, 30 iterations)")


def _stereo_takes(config: dict, number: int) -> set[str]:
    """The takes of subject ``number`` (1-based) that are stereo pairs."""
    st = config["synthetic"].get("stereo") or {}
    return set(st.get("takes", [])) if number in st.get("subjects", []) else set()


def _other_modality(config: dict, number: int) -> str | None:
    """The synthetic modality other than range and stereo of subject ``number``, if any."""
    for key in ("mesh", "rgbd"):
        if number in (config["synthetic"].get(key) or {}).get("subjects", []):
            return key
    return None


def _scan(config: dict, subject: str, t: dict, stereo: bool) -> dict:
    """One take's range image, landmarks and truth, as ingest hands them on."""
    from scan2morph.scan import reconstruct_stereo
    from scan2morph.synth.cohort import make_take
    from scan2morph.synth.stereo import make_stereo_take

    syn = config["synthetic"]
    args = (subject, t["label"], t["kind"], t["take"], int(syn["seed"]))
    if not stereo:
        return make_take(*args, syn["scanner"])
    take = make_stereo_take(*args, dict(syn["stereo"]["rig"]))
    xyz, _ = reconstruct_stereo(
        take["left"], take["right"], take["calib"], dict(config["stereo"]), source=t["take"]
    )
    return {"xyz": xyz, "landmarks": take["landmarks"], "truth": take["truth"]}


def simulate(config: dict, template, subject: str, stereo: set[str] = frozenset()) -> tuple:
    """A subject's takes as the pipeline sees them: repaired, template fitted.

    Returns
    -------
    meshes : dict take -> fit_take's output
    truths : dict take -> Truth
    """
    from scan2morph.evaluate.truth import Truth
    from scan2morph.scan import repair_range
    from scan2morph.stages.fit import Params as FitParams
    from scan2morph.template import fit_take

    tpl = config["template"]
    meshes, truths = {}, {}
    for t in _range_takes(config):
        take = _scan(config, subject, t, t["take"] in stereo)
        xyz, _ = repair_range(take["xyz"], dict(config["repair"]), source=t["take"])
        meshes[t["take"]] = fit_take(
            template,
            take["landmarks"],
            xyz,
            (xyz.shape[1], xyz.shape[0]),
            fiducial_set=tpl["fiducials"].get(t["kind"], "closed"),
            source=f"{subject}/{t['take']}",
            rules=FitParams.from_config(config).rules,
        )
        truths[t["take"]] = Truth.from_arrays(take["truth"])
    return meshes, truths


def _range_takes(config: dict) -> list[dict]:
    return [t for t in config["synthetic"]["takes"] if t.get("modality", "range") == "range"]


def cohort(config_path: Path, n_subjects: int | None) -> list[dict]:
    """Alignment errors against the truth of every take of ``n_subjects`` synthetic subjects."""
    import yaml

    from scan2morph.errors import InputError
    from scan2morph.evaluate.mesh import alignment_accuracy
    from scan2morph.stages.align import Params, grow_indices
    from scan2morph.template import build_template, subdivide_template
    from scan2morph.template.regions import icp_region, named_indices

    config = yaml.safe_load(config_path.read_text())
    n_subjects = int(config["synthetic"]["subjects"]) if n_subjects is None else n_subjects
    template = build_template()
    prm = Params.from_config(config)  # as the align stage reads it
    fine = subdivide_template(template, prm.levels)
    pairs = named_indices(fine, prm.point_pairs, "align.point_pairs")
    stable = np.flatnonzero(icp_region(fine, prm.icp_region))
    grow = grow_indices(fine, prm.grow_into)
    takes = _range_takes(config)
    neutral = next(t["take"] for t in takes if t["kind"] == "neutral")
    rows = []
    for i in range(1, n_subjects + 1):
        subject = f"{config['synthetic']['prefix']}{i:02d}"
        other = _other_modality(config, i)
        if other:
            print(f"{subject:>8} skipped: {other} takes are not simulated here", flush=True)
            continue
        stereo = _stereo_takes(config, i)
        meshes, truths = simulate(config, template, subject, stereo)
        n = meshes[neutral]
        for t in takes:
            if t["take"] == neutral:
                continue
            m = meshes[t["take"]]
            row = {"subject": subject, "take": t["take"], "kind": t["kind"]}
            row["modality"] = "stereo" if t["take"] in stereo else "range"
            try:
                res = align_take(
                    AlignMeshes(m["vertices"], m["valid"], n["vertices"], n["valid"], fine.faces),
                    pairs,
                    stable,
                    prm.icp,
                    source=f"{subject}/{t['take']}",
                    grow_indices=grow,
                )
            except InputError as exc:
                rows.append(row | {"error": str(exc)})
                continue
            acc = alignment_accuracy(
                res.transform, m["vertices"], m["valid"], truths[t["take"]], truths[neutral]
            )
            ok = getattr(res, "ok", None)
            row |= {
                "rot_deg": acc["rotation_deg"],
                "t_mm": acc["translation_mm"],
                "fitness": res.fitness,
                "rmse_mm": res.inlier_rmse,
                "plane_mm": getattr(res, "residual_rmse", float("nan")),
                "noise_take": getattr(res, "noise_take", float("nan")),
                "noise_neutral": getattr(res, "noise_neutral", float("nan")),
                "limit_mm": getattr(res, "rmse_limit", float("nan")),
                "limit_kind": getattr(res, "rmse_limit_kind", "-"),
                "kept": getattr(res, "inlier_fraction", float("nan")),
                "iterations": res.iterations,
                "converged": res.converged,
                "ok": ok,
                "problems": list(getattr(res, "problems", ())),
                "recovery": list(getattr(res, "recovery", ())),
            }
            rows.append(row)
            _print_row(row)
    return rows


_HEADER = (
    f"{'subject':>8} {'take':>7} {'scan':>6} {'rot deg':>8} {'t mm':>7} {'fitness':>7} "
    f"{'plane mm':>8} {'noise t':>7} {'noise n':>7} {'limit':>7} {'kept':>5} "
    f"{'it':>4} {'conv':>5} {'ok':>5} recovery / problems"
)


def _print_row(r: dict) -> None:
    verdict = "-" if r["ok"] is None else ("ok" if r["ok"] else "FLAG")
    star = "*" if r["limit_kind"] == "absolute" else " "
    print(
        f"{r['subject']:>8} {r['take']:>7} {r['modality']:>6} {r['rot_deg']:>8.3f} "
        f"{r['t_mm']:>7.3f} {r['fitness']:>7.3f} {r['plane_mm']:>8.3f} {r['noise_take']:>7.3f} "
        f"{r['noise_neutral']:>7.3f} {r['limit_mm']:>6.3f}{star} {r['kept']:>5.2f} "
        f"{r['iterations']:>4d} {str(r['converged']):>5} {verdict:>5} "
        f"{'; '.join(r['recovery'] + r['problems'])}",
        flush=True,
    )


def _summary(rows: list[dict]) -> None:
    print(f"{'kind':>10} {'n':>3} {'max deg':>8} {'max mm':>7} {'flagged':>7} {'errors':>6}")
    for kind in ("viseme", "expression"):
        rs = [r for r in rows if r["kind"] == kind]
        ok = [r for r in rs if "error" not in r]
        if not rs:
            continue
        deg = max((r["rot_deg"] for r in ok), default=float("nan"))
        mm = max((r["t_mm"] for r in ok), default=float("nan"))
        flagged = sum(r["ok"] is False for r in ok)
        print(f"{kind:>10} {len(rs):>3} {deg:>8.3f} {mm:>7.3f} {flagged:>7} {len(rs) - len(ok):>6}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=Path(__file__).parents[1] / "config/config.yaml")
    ap.add_argument("--subjects", type=int, default=None, help="default: synthetic.subjects")
    ap.add_argument("--timing", action="store_true", help="time align_take instead")
    args = ap.parse_args()
    if args.timing:
        timing()
        return
    print(_HEADER)
    rows = cohort(args.config, args.subjects)
    for r in rows:
        if "error" in r:
            print(f"{r['subject']:>8} {r['take']:>7} failed: {r['error']}")
    _summary(rows)


if __name__ == "__main__":
    main()
