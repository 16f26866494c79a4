"""Time and memory of the modal basis: shell assembly and eigensolve against DOF count and k.

The mesh is a face-sized half-ellipsoid cap (150 x 190 x 60 mm, open rim, clamped), meshed
with (n+1)^2 vertices so that 6 (n+1)^2 is the requested DOF count. Each case runs in a fresh
subprocess so that its peak RSS (``resource.getrusage``: after import, after assembly, after
the eigensolve) is its own; with ``--trace``, ``tracemalloc`` also gives the peak of
Python/NumPy allocations per stage (SuperLU's factor lives outside it, in the RSS).

BLAS threads are set per case with ``--blas-threads`` (default 1): on two cores the
triangular solves run on two threads of their own, and measured with OpenBLAS on two threads
as well the solve threads and BLAS's spinning threads fight over the cores (the eigensolve
took 13 s instead of 8 s for 60k DOF / 100 modes).

The issue's goal: 60,000 DOF and 100 modes in under 10 s on 2 cores (the paper: about 5 min
for 15,000 DOF with block Lanczos in its FE software).

Usage::

    .venv/bin/python benchmarks/bench_modal.py                      # the full table
    .venv/bin/python benchmarks/bench_modal.py --dofs 60000 --ks 100 --methods block arpack
    .venv/bin/python benchmarks/bench_modal.py --blas-threads 2    # BLAS threads per case
    .venv/bin/python benchmarks/bench_modal.py --physics skin      # the default preset's model
    .venv/bin/python benchmarks/bench_modal.py --repeat 3          # each time the fastest of 3

``total`` is the wall time of assembly and eigensolve, ``cpu`` their CPU time (all threads):
with one solve thread and one BLAS thread it is the wall time an idle machine would give.
``DOF`` is the model's layout (six per vertex), ``free`` the DOFs solved: the ``skin`` preset is
a membrane (translations only), so ``--dofs 120000 --physics skin`` solves 60,000.

``--reconstruction RUN SUBJECT`` measures instead what the basis rebuilds on a finished run
(``RUN/results/{SUBJECT}/motion.h5``, ``RUN/resources/template.npz``): the modal stage with the
paper's boundary (``fixed_outline: all``) and with the still outline (``still``), printing each
expression's reconstruction error (total / normal / tangential, mm) per K, the fewest modes
reaching the target, and how much of the displacement sits on the outline; for a synthetic
subject also the same for its true material motion (``results/synthetic/{SUBJECT}/truth``),
the error a perfect correspondence would leave::

    .venv/bin/python benchmarks/bench_modal.py --reconstruction . synth01 --config config/config.yaml
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys


def cap_mesh(n: int, radii=(75.0, 95.0, 60.0)):
    """Half-ellipsoid cap with (n+1)^2 vertices and 2 n^2 triangles."""
    import numpy as np

    u = np.linspace(-1.0, 1.0, n + 1)
    uu, ww = np.meshgrid(u, u, indexing="xy")
    x = uu * np.sqrt(1 - ww**2 / 2)
    y = ww * np.sqrt(1 - uu**2 / 2)
    z = np.sqrt(1 - 0.9 * (x**2 + y**2))
    vertices = np.c_[radii[0] * x.ravel(), radii[1] * y.ravel(), radii[2] * z.ravel()]
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    p = (j * (n + 1) + i).ravel()
    faces = np.r_[np.c_[p, p + 1, p + n + 2], np.c_[p, p + n + 2, p + n + 1]]
    return vertices, faces


def case_model(vertices, faces, physics: str):
    """K, M, the fixed DOFs and the shift of the cap: the paper's clamped steel shell, or the
    ``skin`` preset's model (tensioned skin on its foundation, free rim, tied on the upper
    half, the lower half its mimic skin; as the preset says, a membrane or a soft shell)."""
    import numpy as np

    from scan2morph.modal import ModalParams, assemble, boundary_vertices, fixed_dofs
    from scan2morph.modal.basis import _free_shift, _matrices
    from scan2morph.modal.fem import ShellMaterial
    from scan2morph.stages.modal import PRESETS

    if physics == "paper":
        k_mat, m_mat = assemble(vertices, faces, 1.0)
        return k_mat, m_mat, fixed_dofs(boundary_vertices(faces), "all"), 0.0
    p = PRESETS["skin"]
    keys = ("tension_n_per_mm", "foundation_n_per_mm3", "tether_n_per_mm3")
    mimic = ("mimic_tension_factor", "mimic_foundation_factor", "mimic_mass_factor")
    params = ModalParams(
        thickness_mm=p["thickness_mm"],
        material=ShellMaterial(
            p["youngs_modulus_mpa"],
            p["poisson_ratio"],
            p["density_t_per_mm3"],
            rotary_inertia=p["rotary_inertia"],
        ),
        mass=p["mass"],
        tether_normal_n_per_mm3=p["tether_normal_n_per_mm3"],
        **{key: p[key] for key in keys + mimic},
    )
    thickness = np.full(len(faces), float(p["thickness_mm"]))
    regions = (vertices[:, 1] > 0, (vertices[:, 1] <= 0).astype(float))  # tied; mimic skin
    k_mat, m_mat = _matrices(vertices, faces, thickness, params, regions, "cap")
    rotations = not getattr(params, "has_shell", True)  # a membrane has none
    fixed = fixed_dofs(np.full(len(vertices), rotations), "rotations" if rotations else "all")
    return k_mat, m_mat, fixed, _free_shift(k_mat, m_mat)


def run_case(
    dofs: int, k: int, method: str, solve_threads: int, trace: bool, physics: str = "paper"
) -> dict:
    """One measurement, in this process; with ``trace`` the stages are rerun under
    tracemalloc for the peak of Python/NumPy allocations (tracing slows them down, so the
    times come from the untraced run)."""
    import resource
    import time
    import tracemalloc

    import numpy as np

    from scan2morph.modal import SolverOptions, solve_modes

    n = max(2, round(np.sqrt(dofs / 6)) - 1)
    vertices, faces = cap_mesh(n)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0, c0 = time.perf_counter(), time.process_time()
    k_mat, m_mat, fixed, shift = case_model(vertices, faces, physics)
    t_asm, c_asm = time.perf_counter() - t0, time.process_time() - c0
    rss_asm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0, c0 = time.perf_counter(), time.process_time()
    options = SolverOptions(method=method, threads=solve_threads, shift=shift)
    freqs, modes = solve_modes(k_mat, m_mat, fixed, k, options)
    t_eig, c_eig = time.perf_counter() - t0, time.process_time() - c0
    rss_eig = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    free = np.setdiff1d(np.arange(k_mat.shape[0]), fixed)
    kq = (k_mat @ modes)[free]
    lam = (2 * np.pi * freqs) ** 2
    res = np.linalg.norm(kq - (m_mat @ modes)[free] * lam, axis=0) / np.linalg.norm(kq, axis=0)
    orth = np.abs(modes.T @ (m_mat @ modes) - np.eye(k)).max()
    py_asm = py_eig = float("nan")
    if trace:
        del modes
        tracemalloc.start()
        k_mat, m_mat, fixed, shift = case_model(vertices, faces, physics)
        py_asm = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.reset_peak()
        solve_modes(k_mat, m_mat, fixed, k, options)
        py_eig = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    return {
        "dofs": int(k_mat.shape[0]),
        "free": int(free.size),
        "k": k,
        "method": method,
        "assemble_s": t_asm,
        "eigen_s": t_eig,
        "cpu_s": c_asm + c_eig,
        "py_peak_assemble_mb": py_asm,
        "py_peak_eigen_mb": py_eig,
        "rss_base_mb": rss0,
        "rss_after_assemble_mb": rss_asm,
        "rss_peak_mb": rss_eig,
        "f1_hz": float(freqs[0]),
        "fk_hz": float(freqs[-1]),
        "max_rel_residual": float(res.max()),
        "max_orth_error": float(orth),
    }


def reconstruction(run: str, subject: str, config: str, ks: list[int]) -> None:
    """Print the reconstruction split of a finished run's expressions for both boundaries."""
    from pathlib import Path

    import numpy as np
    import yaml

    from scan2morph.evaluate.motion import template_lip_sides, true_motions
    from scan2morph.evaluate.truth import read_truth
    from scan2morph.modal.subject import rms_length
    from scan2morph.stages import Subject, modal
    from scan2morph.store import paths, read_part
    from scan2morph.template import load_template, subdivide_template
    from scan2morph.template.regions import upper_face

    root = Path(run)
    cfg = yaml.safe_load(Path(config).read_text())
    data = read_part(root / "results" / subject / "motion.h5")
    template = load_template(root / "resources" / "template.npz")
    fine = subdivide_template(template, int(cfg["template"]["subdivision_levels"]))
    takes = {k.split("/")[2] for k in data if k.startswith("/visemes/")}
    exprs = sorted({k.split("/")[2] for k in data if k.startswith("/expressions/")})
    kinds = (
        {"neutral": "neutral"} | dict.fromkeys(takes, "viseme") | dict.fromkeys(exprs, "expression")
    )
    labels = {t: t.rstrip("0123456789") or t for t in kinds}
    neutral = data[paths.neutral("vertices")]
    truth_dir = root / "results" / "synthetic" / subject / "truth"
    true = {}
    if truth_dir.is_dir():
        rest = read_truth(truth_dir / "neutral.npz")
        takes = {t: read_truth(truth_dir / f"{t}.npz") for t in exprs}
        true = true_motions(neutral, rest, takes, template_lip_sides(fine.vertices))
    fields = {t: data[paths.expression(t, "displacement")] for t in exprs}
    for policy in ("all", "still"):
        section = dict(cfg["modal"], fixed_outline=policy, reconstruction_k=ks)
        params = modal.Params.from_config(cfg | {"modal": section}).with_threads(2)
        subj = Subject(subject, kinds, labels)
        part = modal.run(template, subj, data, params)
        d = part.datasets
        fixed, outline = d[paths.modal("fixed_vertices")], np.zeros(len(neutral), bool)
        outline[fine.boundary] = True
        print(
            f"\n== fixed_outline: {policy}: {int(fixed.sum())} of {int(outline.sum())} "
            f"outline vertices clamped, f1 {d[paths.modal('frequencies_hz')][0]:.0f} Hz"
        )
        print(part.files["reconstruction"].round(2).to_string(index=False))
        for t in exprs:
            line = (
                f"{t}: displacement RMS {rms_length(fields[t], np.ones(len(neutral), bool)):.2f} mm, "
                f"on the outline {rms_length(fields[t], outline):.2f}, on the clamped part "
                f"{rms_length(fields[t], fixed):.2f}"
            )
            if t in true:
                line += (
                    f"; true motion {rms_length(true[t], np.ones(len(neutral), bool)):.2f}, "
                    f"on the outline {rms_length(true[t], outline):.2f}, clamped "
                    f"{rms_length(true[t], fixed):.2f}"
                )
            print(line)
        if true:  # what a perfect correspondence would leave: the basis on the true motion
            choice = modal.outline_choice(fine, subj, data, fields, params)
            from scan2morph.modal.subject import ExpressionFields, NeutralShell, subject_modal

            shell = NeutralShell(neutral, fine.faces, upper_face(fine, params.stiff_above))
            expressions = ExpressionFields(true, labels, [], ks, params.target_rms_mm)
            _, dt = subject_modal(shell, params.modal, expressions, subject, fixed=choice)
            print("true material motion:")
            for t in exprs:
                parts = [dt[paths.expression(t, k)] for k in modal.RECONSTRUCTION_PARTS.values()]
                print(
                    f"  {t}: "
                    + "  ".join(
                        f"K={k}: {a:.2f}/{b:.2f}/{c:.2f}"
                        for k, a, b, c in zip(ks, *parts, strict=True)
                    )
                    + f"  modes to target: {dt[paths.expression(t, 'modes_to_target')]}"
                )


def _fastest(cmd: list[str], env: dict, repeat: int) -> dict | str:
    """The case run ``repeat`` times in fresh processes, each time its fastest (on a shared
    machine the slower runs measure the neighbours); the first failure's stderr instead."""
    runs = []
    for _ in range(max(1, repeat)):
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        if proc.returncode:
            return proc.stderr.strip()
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    out = dict(runs[0])
    for key in ("assemble_s", "eigen_s", "cpu_s"):
        out[key] = min(r[key] for r in runs)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--dofs", type=int, nargs="+", default=[5000, 15000, 30000, 60000])
    ap.add_argument("--ks", type=int, nargs="+", default=[20, 50, 100])
    ap.add_argument("--methods", nargs="+", default=["block", "arpack"])
    ap.add_argument("--blas-threads", type=int, default=1)
    ap.add_argument(
        "--repeat", type=int, default=1, help="runs per case; each time is the fastest run's"
    )
    ap.add_argument("--solve-threads", type=int, default=2)
    ap.add_argument(
        "--trace", action="store_true", help="also measure Python peaks with tracemalloc"
    )
    ap.add_argument("--case", nargs=3, metavar=("DOFS", "K", "METHOD"), help=argparse.SUPPRESS)
    ap.add_argument(
        "--physics",
        choices=["paper", "skin"],
        default="paper",
        help="the paper's clamped steel shell or the skin preset (free, tensioned, on a foundation)",
    )
    ap.add_argument("--reconstruction", nargs=2, metavar=("RUN", "SUBJECT"))
    ap.add_argument("--config", default="config/config.yaml")
    args = ap.parse_args()
    if args.reconstruction:
        ks = args.ks if args.ks != [20, 50, 100] else [1, 5, 10, 20, 50, 100]
        reconstruction(*args.reconstruction, args.config, ks)
        return
    if args.case:
        dofs, k, method = int(args.case[0]), int(args.case[1]), args.case[2]
        out = run_case(dofs, k, method, args.solve_threads, args.trace, args.physics)
        print(json.dumps(out))
        return
    env = dict(os.environ, OPENBLAS_NUM_THREADS=str(args.blas_threads))
    env["OMP_NUM_THREADS"] = str(args.blas_threads)
    print(
        f"BLAS threads {args.blas_threads}, solve threads {args.solve_threads}; "
        "times in s, memory in MiB"
    )
    head = (
        f"{'DOF':>7} {'free':>7} {'k':>4} {'method':>7} {'assemble':>9} {'eigen':>7} "
        f"{'total':>7} {'cpu':>7} {'py_asm':>7} {'py_eig':>7} {'rss0':>6} {'rss_asm':>7} {'rss':>7} "
        f"{'f1_hz':>9} {'fk_hz':>9} "
        f"{'resid':>8} {'orth':>8}"
    )
    print(head)
    print("-" * len(head))
    results = {}
    for dofs in args.dofs:
        for k in args.ks:
            for method in args.methods:
                cmd = [sys.executable, __file__, "--case", str(dofs), str(k), method]
                cmd += ["--solve-threads", str(args.solve_threads)] + ["--trace"] * args.trace
                cmd += ["--physics", args.physics]
                r = _fastest(cmd, env, args.repeat)
                if isinstance(r, str):
                    print(f"{dofs:>7} {k:>4} {method:>7} failed: {r[-300:]}")
                    continue
                results[(dofs, k, method)] = r
                print(
                    f"{r['dofs']:>7} {r['free']:>7} {k:>4} {method:>7} {r['assemble_s']:>9.2f} "
                    f"{r['eigen_s']:>7.2f} {r['assemble_s'] + r['eigen_s']:>7.2f} {r['cpu_s']:>7.2f} "
                    f"{r['py_peak_assemble_mb']:>7.0f} {r['py_peak_eigen_mb']:>7.0f} "
                    f"{r['rss_base_mb']:>6.0f} {r['rss_after_assemble_mb']:>7.0f} "
                    f"{r['rss_peak_mb']:>7.0f} {r['f1_hz']:>9.2f} {r['fk_hz']:>9.2f} "
                    f"{r['max_rel_residual']:>8.1e} {r['max_orth_error']:>8.1e}",
                    flush=True,
                )
    for (dofs, k, method), r in results.items():
        ref = results.get((dofs, k, "arpack"))
        if method != "arpack" and ref is not None:
            diff = abs(r["fk_hz"] / ref["fk_hz"] - 1)
            print(f"{dofs} DOF, k={k}: {method} vs arpack, relative difference of f_k {diff:.1e}")


if __name__ == "__main__":
    main()
