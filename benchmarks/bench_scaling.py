"""The cost model of a cohort (issue #17): how wall time, CPU time, memory and store size grow
with the number of subjects.

``.venv/bin/python benchmarks/bench_scaling.py [--subjects 1 2 4 8] [--width 320 --height 240]
[--cores 2] [--slurm] [--keep DIR]`` runs the default workflow target (stores, figures, reports,
accuracy, cohort summary) on a synthetic cohort of each size, each in a fresh working directory,
locally or (``--slurm``) with ``profiles/slurm`` on the throw-away single-node SLURM cluster of
the tests (``tests/support/slurm_cluster.py``, started for each size; needs root, ``slurm-wlm``
and ``munge`` as the SLURM test does),
with the default config's takes (one neutral, five visemes, four expressions: 10 per subject), all
range scans (no stereo, mesh or RGB-D takes, so that every subject costs the same) at a reduced image size
(``--width/--height``, the focal length scaled with them; the default config scans 640 x 480). It
prints per cohort size the wall time, the CPU time of the whole run (:class:`CpuMeter`: every
process the run started, Snakemake's scheduler and, under SLURM, the daemons, the job scripts
and the Snakemake each job starts), the largest job's peak memory, the store sizes, and the per-subject and
per-take figures; then the job time per rule (Snakemake's benchmark files) split into per-take
rules and per-subject rules, and the extrapolation to ``--database`` subjects/scans on
``--extrapolate-cores`` cores. Nothing is asserted; the printed tables are the measurement.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from scan2morph.stages.stage_job import SUBJECT_STAGES, TAKE_STAGES

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]  # the test support: the SLURM cluster and its run's arguments
SNAKEMAKE = Path(sys.executable).with_name("snakemake")
#: Rules that run once per take (the stages of one job per take, rule ``take``, since issue #35);
#: every other rule runs once per subject (template, cohort: once;
#: the synthetic subjects' generators are left out of the extrapolation: real scans are read).
PER_TAKE = TAKE_STAGES
#: The jobs that run several stages (issue #35): the folder of their benchmark files under
#: ``benchmarks/``, their rule and their stages (each stage's line under benchmarks/rules/).
MULTI_STAGE = {"takes": ("take", TAKE_STAGES), "subjects": ("subject", SUBJECT_STAGES)}
ONCE = ("template", "cohort")


def write_config(work: Path, subjects: int, width: int, height: int) -> Path:
    base = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["synthetic"]["scanner"]
    scale = width / base["width"]
    (work / "subjects.tsv").write_text(
        "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor\tleft\tright\tcalibration\tlandmarks\n"
    )
    cfg = dict(
        subjects="subjects.tsv",
        synthetic=dict(
            subjects=subjects,
            scanner=dict(width=width, height=height, focal_px=base["focal_px"] * scale),
            # every subject of range scans, so that each costs the same
            stereo=dict(subjects=[]),
            mesh=dict(subjects=[]),
            rgbd=dict(subjects=[]),
        ),
        sweeps="sweeps.tsv",
    )
    path = work / "scaling.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


class CpuMeter:
    """CPU time (user + system, s) of every process this one starts from now on.

    The process moves itself into a cgroup of its own (cgroup v2 ``cpu.stat``, or v1
    ``cpuacct``) when it may, so that everything a run starts counts, the SLURM daemons and the
    jobs they run included (slurmd's job steps are not processes this one waits for);
    otherwise the CPU of the children this process waited for (``RUSAGE_CHILDREN``), which
    misses what a SLURM cluster runs. ``kind`` says which.
    """

    def __init__(self):
        self.kind, self._file, self._group = "rusage", None, None
        v2 = Path("/sys/fs/cgroup/cgroup.controllers").is_file()
        base, name = (
            (Path("/sys/fs/cgroup"), "cpu.stat")
            if v2
            else (Path("/sys/fs/cgroup/cpuacct"), "cpuacct.usage")
        )
        if not (base / name).is_file():
            return
        group = base / f"bench_scaling-{os.getpid()}"
        try:
            group.mkdir()
            (group / "cgroup.procs").write_text(str(os.getpid()))
        except OSError:
            return
        self.kind, self._file, self._group = f"cgroup ({group})", group / name, group

    def close(self) -> None:
        """Move this process back to the parent cgroup and remove its own (when empty)."""
        if self._group is not None:
            try:
                (self._group.parent / "cgroup.procs").write_text(str(os.getpid()))
                self._group.rmdir()
            except OSError:
                pass

    def seconds(self) -> float:
        """CPU seconds so far (a running total: take differences)."""
        if self._file is None:
            r = resource.getrusage(resource.RUSAGE_CHILDREN)
            return r.ru_utime + r.ru_stime
        text = self._file.read_text()
        if self._file.name == "cpu.stat":  # v2: usage_usec
            return int(text.split("usage_usec")[1].split()[0]) / 1e6
        return int(text) / 1e9  # v1 cpuacct.usage: ns


def snakemake_command(config: Path, args) -> list[str]:
    """The run's Snakemake command: local on ``args.cores`` cores, or with the SLURM profile."""
    common = ["-s", str(ROOT / "Snakefile"), "--configfile", str(ROOT / "config" / "config.yaml")]
    if not args.slurm:
        return [str(SNAKEMAKE), "--cores", str(args.cores), *common, str(config), "--quiet"]
    from tests.support.slurm_run import CLUSTER_ARGS

    profile = ["--workflow-profile", str(ROOT / "profiles" / "slurm"), *CLUSTER_ARGS]
    return [str(SNAKEMAKE), *profile, *common, str(config), "--quiet"]


def run(work: Path, subjects: int, args, meter: CpuMeter) -> dict:
    """One run of the default target (locally or under SLURM); returns its measurements."""
    config = write_config(work, subjects, args.width, args.height)
    cmd = snakemake_command(config, args)
    env, cluster = dict(os.environ), None
    before = meter.seconds()
    t0 = time.perf_counter()
    if args.slurm:  # started and stopped within the measurement: the daemons' CPU counts too
        from tests.support.slurm_cluster import SlurmCluster

        cluster = SlurmCluster(work / "cluster")
        cluster.start()
        env = {**cluster.env, "PYOPENGL_PLATFORM": "osmesa"}
    try:
        with open(work / "snakemake.out", "w") as out:
            code = subprocess.run(
                cmd, cwd=work, env=env, stdout=out, stderr=subprocess.STDOUT
            ).returncode
    finally:
        if cluster is not None:
            cluster.stop()
    wall = time.perf_counter() - t0
    cpu = meter.seconds() - before
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if code:
        sys.exit(f"snakemake failed ({code}): see {work / 'snakemake.out'}")
    lines = job_benchmarks(work)
    jobs = lines[lines.job]
    takes = len(yaml.safe_load(config.read_text()).get("synthetic", {}).get("takes", [])) or len(
        yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["synthetic"]["takes"]
    )
    stores = [work / "results" / s / f"{s}.h5" for s in synthetic_ids(subjects)]
    results = sum(f.stat().st_size for f in (work / "results").rglob("*") if f.is_file())
    return dict(
        slurm=bool(args.slurm),
        subjects=subjects,
        takes=subjects * takes,
        jobs=len(jobs),
        wall_s=wall,
        cpu_s=cpu,
        job_s=jobs.s.sum(),
        peak_rss_mb=jobs.max_rss.max(),
        # the largest process Snakemake waited for so far in this series, Snakemake included (KiB)
        peak_process_mb=(after.ru_maxrss) / 1024,
        store_mb=sum(f.stat().st_size for f in stores) / 2**20,
        results_mb=results / 2**20,
        rules=lines,
    )


def synthetic_ids(n: int) -> list[str]:
    return [f"synth{i:02d}" for i in range(1, n + 1)]


def job_benchmarks(work: Path) -> pd.DataFrame:
    """Every benchmark line (benchmarks/rules/<rule>/...tsv) with its rule, and whether it is a
    job's (column ``job``): where a take's or a subject's stages run in one job (rules ``take``
    and ``subject``, their lines under benchmarks/takes/ and benchmarks/subjects/), the stages'
    lines are not jobs, the multi-stage jobs' are (rule ``take`` or ``subject``)."""
    rows = []
    bench = work / "benchmarks"
    jobs = {f: job for f, job in MULTI_STAGE.items() if (bench / f).is_dir()}
    inside = {stage for _, stages in jobs.values() for stage in stages}
    for f in (bench / "rules").rglob("*.tsv"):
        d = pd.read_csv(f, sep="\t")
        d["rule"] = f.relative_to(bench / "rules").parts[0]
        d["job"] = d["rule"].iloc[0] not in inside
        rows.append(d)
    for folder, (rule, _) in jobs.items():
        for f in (bench / folder).rglob("*.tsv"):
            d = pd.read_csv(f, sep="\t")
            d["rule"], d["job"] = rule, True
            rows.append(d)
    return pd.concat(rows, ignore_index=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--subjects", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument(
        "--slurm",
        action="store_true",
        help="run under profiles/slurm on the tests' throw-away SLURM cluster (needs root)",
    )
    ap.add_argument("--keep", type=Path, help="keep the working directories under DIR")
    ap.add_argument(
        "--summarize",
        type=Path,
        metavar="DIR",
        help="run nothing: print the tables of the sizes that finished in DIR (a --keep DIR)",
    )
    ap.add_argument("--database", type=int, nargs=2, default=[470, 4000], metavar=("SUBJ", "SCANS"))
    ap.add_argument("--extrapolate-cores", type=int, nargs="+", default=[2, 16, 64, 256])
    args = ap.parse_args(argv)

    if args.summarize:
        runs = finished_runs(args.summarize)
        summarize(runs, args)
        return 0
    root = Path(args.keep or tempfile.mkdtemp(prefix="bench_scaling-"))
    meter = CpuMeter()
    if args.slurm and meter.kind == "rusage":
        sys.exit("--slurm needs a cgroup of its own to count the jobs' CPU (run as root)")
    print(f"CPU measured by {meter.kind}", flush=True)
    runs = []
    for n in args.subjects:
        work = root / f"subjects_{n}"
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        r = run(work, n, args, meter)
        runs.append(r)
        print(
            f"{n} subjects: {r['wall_s']:.0f} s wall, {r['cpu_s']:.0f} s CPU, {r['jobs']} jobs",
            flush=True,
        )
        # each size as it finishes, so that an interrupted series keeps what ran
        with open(root / "scaling.jsonl", "a") as out:
            out.write(json.dumps({k: float(v) for k, v in r.items() if k != "rules"}) + "\n")

    meter.close()
    summarize(runs, args)
    print(f"working directories: {root}")
    return 0


def finished_runs(root: Path) -> list[dict]:
    """The sizes recorded in ``root/scaling.jsonl`` with their jobs' benchmark files."""
    runs = [json.loads(line) for line in (root / "scaling.jsonl").read_text().splitlines()]
    for r in runs:
        r["subjects"], r["takes"], r["jobs"] = int(r["subjects"]), int(r["takes"]), int(r["jobs"])
        r["rules"] = job_benchmarks(root / f"subjects_{r['subjects']}")
    return runs


def linear_fit(table: pd.DataFrame) -> None:
    """Least-squares lines ``a + b * subjects`` through the CPU and wall times: ``b`` is the
    cost of one more subject, ``a`` the fixed cost of a run (DAG, template, cohort summary);
    the largest residual says how far the sizes are from a line."""
    if len(table) < 2:
        return
    n = table.subjects.to_numpy(float)
    for col in ("cpu_s", "wall_s", "job_s"):
        y = table[col].to_numpy(float)
        b, a = np.polyfit(n, y, 1)
        resid = y - (a + b * n)
        print(
            f"{col}: {a:.0f} s + {b:.0f} s x subjects "
            f"(largest residual {np.abs(resid).max():.0f} s = "
            f"{100 * np.abs(resid / y).max():.1f} % of its size)"
        )


def summarize(runs: list[dict], args) -> None:
    """Print the per-size table, the job time per rule and the extrapolation."""
    where = "SLURM (profiles/slurm)" if runs[0].get("slurm") else f"{args.cores} cores, local"
    print(f"\n{args.width} x {args.height} px, {where}, default takes (range scans)")
    table = pd.DataFrame([{k: v for k, v in r.items() if k != "rules"} for r in runs])
    for col in ("wall_s", "cpu_s", "job_s", "store_mb"):
        table[f"{col}/subject"] = table[col] / table.subjects
    table["cpu_s/take"] = table.cpu_s / table.takes
    table["wall_s/take"] = table.wall_s / table.takes
    print(table.round(1).to_string(index=False))
    # under SLURM each job also runs a Snakemake of its own: compare with a local run's figure
    extra = ", the SLURM daemons and each job's own Snakemake" if runs[0].get("slurm") else ""
    per_job = ", ".join(f"{c:.1f} s" for c in table.cpu_s / table.jobs)
    print(f"CPU per job (the run's CPU, Snakemake's scheduler{extra} included): {per_job}")
    linear_fit(table)

    # per rule, from the largest run: job seconds per take (per-take rules: a take job's stages)
    # or per subject (a subject job's stages)
    big = runs[-1]
    jobs = big["rules"][~big["rules"].rule.isin([rule for rule, _ in MULTI_STAGE.values()])]
    per = jobs.groupby("rule").agg(
        jobs=("s", "size"),
        job_s=("s", "sum"),
        job_cpu_s=("cpu_time", "sum"),
        max_s=("s", "max"),
        max_rss_mb=("max_rss", "max"),
    )
    per["per"] = [
        "take"
        if r in PER_TAKE
        else "once"
        if r in ONCE
        else "synthetic"
        if r.startswith("synth_")
        else "subject"
        for r in per.index
    ]
    per["job_s_each"] = per.job_s / per.jobs
    print(f"\njob time per rule ({big['subjects']} subjects, {big['takes']} takes):")
    print(per.round(1).sort_values(["per", "job_s"]).to_string())
    # Each job's CPU time from its benchmark file (user + system of the job's processes, which
    # Snakemake samples, so short-lived ones are missed), scaled so that all jobs add up to the
    # measured CPU time of the run: a split of the measured CPU into per-take and per-subject
    # parts that, unlike the jobs' wall times, does not depend on how busy the machine was.
    cpu_ratio = big["cpu_s"] / per.job_cpu_s.sum()
    take_s = per.job_cpu_s[per.per == "take"].sum() / big["takes"] * cpu_ratio
    subject_s = per.job_cpu_s[per.per == "subject"].sum() / big["subjects"] * cpu_ratio
    n_subj, n_scans = args.database
    total_cpu = n_subj * subject_s + n_scans * take_s
    print(
        f"\nCPU per take {take_s:.1f} s, per subject {subject_s:.1f} s (+ its takes; "
        f"measured CPU / sampled job CPU {cpu_ratio:.2f})"
    )
    print(f"{n_subj} subjects / {n_scans} scans: {total_cpu / 3600:.1f} CPU-hours")
    for cores in args.extrapolate_cores:
        print(f"  on {cores:4d} cores: {total_cpu / cores / 3600:8.2f} h (perfect packing)")
    # a store holds every take's images and meshes: its size follows the takes
    store_per_take = big["store_mb"] / big["takes"]
    results_per_take = big["results_mb"] / big["takes"]
    print(
        f"stores {store_per_take:.2f} MB/take -> {n_scans * store_per_take / 1024:.1f} GB; "
        f"all results {results_per_take:.2f} MB/take -> "
        f"{n_scans * results_per_take / 1024:.1f} GB (at {args.width} x {args.height})"
    )


if __name__ == "__main__":
    sys.exit(main())
