"""Where a run's time goes (issue #35, "profile first"): per rule, the interpreter's start-up and
imports against the job's own work, the functions that take the work, and the scheduler's own
cost on a large sheet.

``.venv/bin/python benchmarks/bench_profile.py [--width 640 --height 480] [--cores 2]
[--dag-subjects 59] [--keep DIR]`` runs the default workflow target on one synthetic subject
(the default config's ten takes, range scans) with ``SCAN2MORPH_PROFILE`` set, so that every job
profiles itself (:func:`scan2morph.jobs.run_job`: cProfile statistics and the CPU time spent
before its body, i.e. the interpreter, Snakemake's script wrapper and the imports). It prints

1. per job rule (``take``: a take's stages in one process; ``subject``: a subject's; and the
   one-stage rules): jobs, mean job wall time (Snakemake's benchmark files), mean start-up CPU
   (paid once a job) and its share of the job; then per stage: its runs, its mean body time and
   its line in its job's benchmark;
2. per rule, the functions with the most time of their own (cProfile ``tottime``, summed over
   the rule's jobs), and the library's own functions with the most cumulative time;
3. the scheduler: the wall and CPU time of a dry run (``snakemake -n``: parsing, the DAG) on a
   cohort of ``--dag-subjects`` synthetic subjects, per subject.

Nothing is asserted; the printed tables are the measurement. Run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import os
import pstats
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
from bench_scaling import MULTI_STAGE, ROOT, SNAKEMAKE, job_benchmarks, write_config

from scan2morph.jobs import PROFILE_ENV

#: Functions of the job machinery, not of the work (left out of the tables).
WRAPPERS = {"run_job", "_profiled", "job", "main", "isolated", "run_take_job", "<module>"}


def run_profiled(work: Path, args) -> Path:
    """One profiled run of the default target on one subject; returns the profile folder."""
    config = write_config(work, 1, args.width, args.height)
    profile = work / "profile"
    env = dict(os.environ, **{PROFILE_ENV: str(profile)})
    cmd = [str(SNAKEMAKE), "--cores", str(args.cores), "-s", str(ROOT / "Snakefile")]
    cmd += ["--configfile", str(ROOT / "config" / "config.yaml"), str(config), "--quiet"]
    with open(work / "snakemake.out", "w") as out:
        code = subprocess.run(cmd, cwd=work, env=env, stdout=out, stderr=subprocess.STDOUT)
    if code.returncode:
        sys.exit(f"snakemake failed ({code.returncode}): see {work / 'snakemake.out'}")
    return profile


def rule_of(stem: str) -> str:
    """The rule of a profile file (``ingest-synth01-neutral`` -> ``ingest``)."""
    return stem.split("-")[0]


def _job_of(stem: str) -> str:
    """The job a profiled stage ran in: ``take-{subject}-{take}`` for a take's stage,
    ``subject-{subject}`` for a subject's (one process each, issue #35), else its own name."""
    stage, *rest = stem.split("-")
    for job, stages in MULTI_STAGE.values():
        if stage in stages:  # a take job is one take's, a subject job one subject's
            return "-".join([job, *rest[: 2 if job == "take" else 1]])
    return stem


def rule_table(work: Path, profile: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per stage: its runs, mean body time and mean stage time (its line in the job's benchmark);
    per job rule (``take``, ``subject`` and the one-stage rules): jobs, mean job wall time, mean
    start-up CPU (the interpreter, Snakemake's wrapper and the imports, paid once a job: the
    first stage it runs records it) and its share of the job's wall time."""
    rows = []
    for f in profile.glob("*.json"):
        rows.append({"rule": rule_of(f.stem), "job": _job_of(f.stem)} | json.loads(f.read_text()))
    runs = pd.DataFrame(rows)
    bench = job_benchmarks(work)
    stage_wall = bench[~bench.job].groupby("rule")["s"].mean().rename("stage_wall_s")
    stages = (
        runs.groupby("rule")
        .agg(runs=("body_wall_s", "size"), body_wall_s=("body_wall_s", "mean"))
        .join(stage_wall, how="left")
        .sort_values("body_wall_s", ascending=False)
    )
    per_job = runs.groupby("job").agg(startup_cpu_s=("startup_cpu_s", "sum"))
    per_job["rule"] = [rule_of(j) for j in per_job.index]
    jobs = per_job.groupby("rule").agg(
        jobs=("startup_cpu_s", "size"), startup_cpu_s=("startup_cpu_s", "mean")
    )
    job_wall = bench[bench.job].groupby("rule")["s"].mean().rename("job_wall_s")
    jobs = jobs.join(job_wall, how="left")
    jobs["startup_share"] = jobs.startup_cpu_s / jobs.job_wall_s
    return stages, jobs.sort_values("job_wall_s", ascending=False)


def top_functions(profile: Path, rule: str, n: int) -> tuple[list[str], list[str]]:
    """The rule's functions by own time, and the library's by cumulative time (summed)."""
    files = sorted(str(f) for f in profile.glob(f"{rule}-*.prof")) + sorted(
        str(f) for f in profile.glob(f"{rule}.prof")
    )
    if not files:
        return [], []
    stats = pstats.Stats(*files)
    entries = [
        (key, value) for key, value in stats.stats.items() if key[2] not in WRAPPERS
    ]  # key: (file, line, function); value: (calls, ncalls, tottime, cumtime, callers)
    own = sorted(entries, key=lambda e: -e[1][2])[:n]
    library = [e for e in entries if "scan2morph" in e[0][0]]
    cumulative = sorted(library, key=lambda e: -e[1][3])[:n]

    def line(entry, index):
        (file, lineno, func), value = entry
        where = file.split("site-packages/")[-1].split("src/")[-1]
        return f"{value[index]:7.2f} s  {func} ({where}:{lineno})"

    return [line(e, 2) for e in own], [line(e, 3) for e in cumulative]


def scheduler(work: Path, subjects: int, args) -> dict:
    """Wall and CPU time of a dry run on ``subjects`` synthetic subjects."""
    config = write_config(work, subjects, args.width, args.height)
    cmd = [str(SNAKEMAKE), "-n", "--quiet", "-s", str(ROOT / "Snakefile")]
    cmd += ["--configfile", str(ROOT / "config" / "config.yaml"), str(config)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return dict(subjects=subjects, wall_s=wall, cpu_s=cpu, cpu_s_per_subject=cpu / subjects)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--top", type=int, default=6, help="functions listed per rule")
    ap.add_argument("--dag-subjects", type=int, nargs="+", default=[1, 59])
    ap.add_argument("--keep", type=Path, help="keep the working directory (DIR/profile)")
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="bench_profile_"))
    try:
        profile = run_profiled(work, args)
        stages, jobs = rule_table(work, profile)
        pd.set_option("display.width", 160)
        print(f"== per job rule, one subject at {args.width} x {args.height} (means over jobs)")
        print(jobs.round(2).to_string())
        print(
            "\n== per stage (means over its runs; a take's stages share one job, a subject's too)"
        )
        print(stages.round(2).to_string())
        for rule in stages.index:
            own, cumulative = top_functions(profile, rule, args.top)
            print(f"\n== {rule}: own time (summed over its jobs)")
            print("\n".join(own))
            print(f"-- {rule}: scan2morph functions, cumulative")
            print("\n".join(cumulative))
        print("\n== scheduler: dry run (parse + DAG)")
        for n in args.dag_subjects:
            dag = work / f"dag{n}"
            dag.mkdir()
            print(scheduler(dag, n, args))
    finally:
        if args.keep:
            shutil.copytree(work, args.keep / work.name)
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
