"""A subject's own jobs (besides its takes), tree against tree: job wall, CPU and profile (issue #35).

``.venv/bin/python benchmarks/bench_subject_jobs.py RUN --trees OLD NEW [--subject synth01]
[--repeat 2] [--cores 1] [--top 8] [--keep DIR]`` copies one subject of a finished run ``RUN``
(its ``results/{subject}``, ``results/synthetic/{subject}`` and ``resources``, modification
times kept) into a scratch folder per tree and re-runs there, with each tree's own Snakefile,
rules and ``src`` (a checkout, e.g. ``git archive <commit> | tar -x -C OLD``), the subject's own
jobs: motion, motion_noise, morph, modal, store, head_meshes, accuracy, the figures and the
report, or the one job that runs them all (rule ``subject``, since issue #35; its record of
up-to-date stages, ``stages.json``, is removed so that every stage runs) (``--forcerun``; the
takes' parts are kept: ``--rerun-triggers mtime``). Trees alternate, each repeat in a fresh
copy.

It prints, per tree and repeat: each rule's job wall time (Snakemake's benchmark file, ``s``;
inside a subject's job, each stage's), the jobs' sum and the CPU seconds of the whole Snakemake run (its children: every job, Snakemake's
own start-up and scheduling included; the benchmark files' sampled ``cpu_time`` misses most of
a short job). Then one more run per tree with every job profiling itself
(``SCAN2MORPH_PROFILE``, :func:`scan2morph.jobs.run_job`): each rule's start-up CPU
(interpreter, Snakemake's script wrapper, imports), its body's CPU (cProfile adds to it) and
the functions with the most time of their own. Last, whether the trees' outputs agree: the
largest absolute difference of every float dataset of the subject's store and
``motion_noise.h5``, ``accuracy.json`` byte for byte, and the figures pixel for pixel (RGB).
Nothing is asserted; the printed tables are the measurement. Run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
from bench_profile import top_functions
from bench_scaling import SNAKEMAKE, job_benchmarks

from scan2morph.jobs import PROFILE_ENV
from scan2morph.stages.stage_job import SUBJECT_STAGES

#: The subject's own rules re-run (a tree without one of them simply has no such job): a rule
#: per stage (the figures once a rule per stage) before issue #35, one job after.
RULES = [
    *(s for s in SUBJECT_STAGES if s != "template_part"),
    *(f"figures_{stage}" for stage in ("fit", "motion", "morph", "modal")),
    "subject",
    "subject_synthetic",
]


def copy_subject(run: Path, work: Path, subject: str) -> None:
    """The subject's finished parts and the run's resources, modification times kept."""
    for part in (Path("results") / subject, Path("results") / "synthetic" / subject):
        if (run / part).exists():
            shutil.copytree(run / part, work / part, symlinks=True)
    # a subject's job runs only its out-of-date stages: without its record, all of them
    (work / "results" / subject / "stages.json").unlink(missing_ok=True)
    shutil.copytree(run / "resources", work / "resources", symlinks=True)


def tree_rules(tree: Path) -> list[str]:
    """The rules of :data:`RULES` that ``tree``'s workflow defines."""
    text = "\n".join(f.read_text() for f in (tree / "workflow" / "rules").glob("*.smk"))
    defined = set(re.findall(r"^rule (\w+):", text, flags=re.MULTILINE))
    defined |= set(re.findall(r"^use rule \w+ as (\w+)", text, flags=re.MULTILINE))
    return [r for r in RULES if r in defined]


def run_tree(tree: Path, run: Path, work: Path, args, profiled: bool = False) -> dict:
    """One re-run of the subject's own jobs with ``tree`` (each job profiling itself when
    ``profiled``); returns the run's measurements."""
    copy_subject(run, work, args.subject)
    config = work / "bench.yaml"
    config.write_text(f"subjects: {tree / 'config' / 'subjects.tsv'}\n")
    targets = [
        f"results/{args.subject}/{name}" for name in ("report.html", "accuracy.json", "meshes/head")
    ]
    cmd = [str(SNAKEMAKE), "--cores", str(args.cores), "-s", str(tree / "Snakefile")]
    cmd += ["-d", str(work), "--configfile", str(tree / "config" / "config.yaml"), str(config)]
    cmd += ["--rerun-triggers", "mtime", "--quiet", "--forcerun", *tree_rules(tree), "--"]
    cmd += targets
    env = dict(os.environ, PYTHONPATH=str(tree / "src"), OMP_NUM_THREADS="1")
    env["OPENBLAS_NUM_THREADS"] = "1"
    env.pop(PROFILE_ENV, None)
    if profiled:
        env[PROFILE_ENV] = str(work / "profile")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with open(work / "snakemake.out", "w") as out:
        code = subprocess.run(cmd, cwd=tree, env=env, stdout=out, stderr=subprocess.STDOUT)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if code.returncode:
        sys.exit(f"snakemake failed ({code.returncode}): see {work / 'snakemake.out'}")
    bench = job_benchmarks(work)
    jobs = bench.groupby("rule")["s"].sum()
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"jobs": jobs, "job_s": bench.s[bench.job].sum(), "run_wall_s": wall, "run_cpu_s": cpu}


def job_cpu_table(work: Path) -> pd.DataFrame:
    """Per rule of a profiled run: its job's start-up CPU (interpreter, Snakemake's script
    wrapper, imports) and its body's CPU (under cProfile, which adds to it), s."""
    rows = {}
    for f in (work / "profile").glob("*.json"):
        times = json.loads(f.read_text())
        rows[f.stem.split("-")[0]] = {
            "startup_cpu_s": times["startup_cpu_s"],
            "body_cpu_s": times.get("body_cpu_s", float("nan")),
        }
    return pd.DataFrame(rows).T.sort_index()


def float_datasets(path: Path) -> dict[str, np.ndarray]:
    """Every float dataset of an HDF5 file."""
    out = {}
    with h5py.File(path, "r") as h5:
        h5.visititems(
            lambda name, obj: (
                out.__setitem__(name, obj[()])
                if isinstance(obj, h5py.Dataset) and obj.dtype.kind == "f"
                else None
            )
        )
    return out


def compare(a: Path, b: Path, subject: str) -> list[str]:
    """How two re-runs' outputs differ (see the module notes)."""
    lines = []
    res_a, res_b = a / "results" / subject, b / "results" / subject
    for name in (f"{subject}.h5", "motion_noise.h5"):
        da, db = float_datasets(res_a / name), float_datasets(res_b / name)
        worst, where = 0.0, ""
        for key in sorted(set(da) | set(db)):
            x, y = da.get(key), db.get(key)
            if x is None or y is None or np.shape(x) != np.shape(y):
                lines.append(f"{name}: {key} only in one, or shapes differ")
                continue
            if not np.array_equal(np.isnan(x), np.isnan(y)):
                lines.append(f"{name}: {key}: NaNs differ")
                continue
            d = float(np.max(np.abs(x - y)[np.isfinite(x)], initial=0.0))
            if d > worst:
                worst, where = d, key
        lines.append(f"{name}: {len(da)} float datasets, largest |difference| {worst:.3g} {where}")
    same = (res_a / "accuracy.json").read_text() == (res_b / "accuracy.json").read_text()
    lines.append(f"accuracy.json: {'identical' if same else 'DIFFERS'}")
    from PIL import Image

    figures = sorted((res_a / "figures").glob("*.png"))
    # compared as RGB: an opaque figure written as RGBA (before 2026-12-05) or RGB shows the same
    differ = [
        p.name
        for p in figures
        if not np.array_equal(
            np.asarray(Image.open(p).convert("RGB")),
            np.asarray(Image.open(res_b / "figures" / p.name).convert("RGB")),
        )
    ]
    lines.append(f"figures: {len(figures) - len(differ)} of {len(figures)} equal pixel for pixel")
    lines += [f"  differs: {name}" for name in differ]
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a finished run (results/, resources/)")
    ap.add_argument("--trees", type=Path, nargs="+", required=True, help="repository checkouts")
    ap.add_argument("--subject", default="synth01")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--cores", type=int, default=1)
    ap.add_argument("--top", type=int, default=8, help="functions listed per rule")
    ap.add_argument("--keep", type=Path, help="work under DIR (kept) instead of a temporary one")
    args = ap.parse_args(argv)
    trees = [t.resolve() for t in args.trees]
    scratch = args.keep or Path(tempfile.mkdtemp(prefix="bench_subject_jobs_"))
    last, table, job_s = {}, {}, {}
    for k in range(args.repeat):
        for i, tree in enumerate(trees):
            work = scratch / f"tree{i}-run{k}"
            shutil.rmtree(work, ignore_errors=True)
            m = run_tree(tree, args.run.resolve(), work, args)
            last[i] = work
            table[(f"tree{i}", k)], job_s[(f"tree{i}", k)] = m["jobs"], m["job_s"]
            print(
                f"tree{i} ({tree}) run {k + 1}: jobs {m['job_s']:6.1f} s wall, "
                f"Snakemake run {m['run_wall_s']:6.1f} s wall, {m['run_cpu_s']:6.1f} CPU-s"
            )
    pd.set_option("display.width", 160)
    jobs = pd.DataFrame(table).fillna(0.0)
    jobs.loc["jobs"] = pd.Series(job_s)  # the jobs' sum (a subject job's stages are in it)
    print(f"\n== job wall time per rule or stage, s ({args.subject}; the benchmark files)")
    print(jobs.round(2).to_string())
    for i, tree in enumerate(trees):
        work = scratch / f"tree{i}-profiled"
        shutil.rmtree(work, ignore_errors=True)
        run_tree(tree, args.run.resolve(), work, args, profiled=True)
        cpu = job_cpu_table(work)
        cpu.loc["sum"] = cpu.sum()
        print(f"\n== tree{i}, a profiled run: CPU per job, s")
        print(cpu.round(2).to_string())
        for rule in cpu.index.drop("sum"):
            own, _ = top_functions(work / "profile", rule, args.top)
            print(f"-- tree{i} {rule}: own time")
            print("\n".join(own))
    for i in range(1, len(trees)):
        print(f"\n== outputs of tree0 and tree{i}")
        print("\n".join(compare(last[0], last[i], args.subject)))
    if not args.keep:
        shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
