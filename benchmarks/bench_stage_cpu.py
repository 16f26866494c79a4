"""A stage's CPU cost, source tree against source tree, on a shared machine (issue #35).

A busy machine makes the workflow's own benchmark files useless for a before/after: their wall
times grow with the load and their CPU times are sampled. This benchmark runs one stage at a
time, each in a fresh interpreter (as a workflow job runs: start-up and imports included), on
the parts of a kept run, alternating between the source trees given, and prints every run's
wall and CPU seconds (user + system of the child) and each tree's median; it then checks that
the trees' outputs agree (largest absolute difference of every float dataset).

``.venv/bin/python benchmarks/bench_stage_cpu.py RUN --src OLD/src NEW/src [--stages align
refine motion_noise] [--repeat 3] [--subject synth01] [--take too]`` where ``RUN`` is a working
directory that ``benchmarks/bench_profile.py --keep`` kept (one synthetic subject, ``synth01``,
the default config's takes) or any finished default run (``make run``: ``--subject`` picks one
of its subjects, e.g. ``synth02``, whose range takes are refined against a stereo neutral) and
each ``--src`` a source tree (e.g. ``git archive <commit> src | tar -x``). Nothing is asserted;
the printed table is the measurement.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
#: The subject by default (a bench_profile run has this one only).
SUBJECT = "synth01"
#: The viseme a take stage is run on by default (the neutral is its reference).
TAKE = "too"

#: The child: rebuild the stage's inputs from the run's parts, run it, save its float datasets.
CHILD = """
import sys
import numpy as np, yaml
from pathlib import Path
from scan2morph.stages import Subject, Take, align, motion_noise, refine
from scan2morph.store import read_part, read_parts
from scan2morph.template import load_template

stage, run, out, subject, take = sys.argv[1:6]
config = yaml.safe_load(open(sys.argv[6]))
kinds = {t["take"]: t["kind"] for t in config["synthetic"]["takes"]}
labels = {t["take"]: t["label"] for t in config["synthetic"]["takes"]}
takes = Path(run) / "results" / subject / "takes"
template = load_template(Path(run) / "resources" / "template.npz")
if stage == "motion_noise":
    used = [t for t, k in kinds.items() if k in ("neutral", "viseme")]
    files = [takes / t / f"{s}.h5" for t in used for s in ("repair", "landmarks")]
    files += [takes / t / "align.h5" for t in used if kinds[t] != "neutral"]
    own = Path(run) / "results" / subject
    files += [own / "consensus.h5"] if (own / "consensus.h5").exists() else []  # the draws' moves
    data = read_parts(files) | read_part(own / "motion.h5")
    params = motion_noise.Params.from_config(config)
    part = motion_noise.run(template, Subject(subject, kinds, labels), data, params)
else:
    module = {"align": align, "refine": refine}[stage]
    stages = ["fit"] if stage == "align" else ["repair", "landmarks", "fit", "align"]
    data = read_parts([takes / t / f"{s}.h5" for t in (take, "neutral") for s in stages])
    one = Take(subject, take, kind=kinds[take], neutral="neutral", label=labels[take], data=data)
    part = module.run(template, one, module.Params.from_config(config))
floats = {k: v for k, v in part.datasets.items() if np.asarray(v).dtype.kind == "f"}
np.savez(out, **{k.replace("/", "|"): v for k, v in floats.items()})
"""


def run_child(
    stage: str, run: Path, src: Path, out: Path, config: Path, which: tuple[str, str]
) -> tuple[float, float]:
    """One fresh-interpreter run of ``stage`` on ``which`` (subject, take) with ``src`` first
    on the path: (wall s, CPU s)."""
    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    cmd = [sys.executable, "-c", CHILD, stage, str(run), str(out), *which, str(config)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def largest_difference(a: Path, b: Path) -> float:
    """The largest absolute difference between two children's float datasets (NaN = NaN)."""
    with np.load(a) as da, np.load(b) as db:
        if set(da) != set(db):
            return float("inf")
        worst = 0.0
        for key in da:
            x, y = da[key], db[key]
            if x.shape != y.shape or not np.array_equal(np.isnan(x), np.isnan(y)):
                return float("inf")
            if x.size:
                worst = max(worst, float(np.nanmax(np.abs(x - y), initial=0.0)))
        return worst


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a bench_profile --keep folder (or its parent)")
    ap.add_argument("--src", type=Path, nargs="+", required=True, help="source trees to compare")
    ap.add_argument("--stages", nargs="+", default=["align", "refine", "motion_noise"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--subject", default=SUBJECT)
    ap.add_argument("--take", default=TAKE, help="the take stage's take")
    args = ap.parse_args(argv)
    run = args.run if (args.run / "results").is_dir() else next(args.run.glob("bench_profile_*"))
    config = ROOT / "config" / "config.yaml"
    own = run / "scaling.yaml"  # a bench_profile run's config; a default run's is the repo's
    scanner = yaml.safe_load((own if own.is_file() else config).read_text())["synthetic"]["scanner"]
    which = (args.subject, args.take)
    print(f"run {run} ({scanner['width']} x {scanner['height']}), subject {args.subject}")
    with tempfile.TemporaryDirectory() as tmp:
        for stage in args.stages:
            times = {src: [] for src in args.src}
            for k in range(args.repeat):
                for i, src in enumerate(args.src):
                    out = Path(tmp) / f"{stage}-{i}.npz"
                    wall, cpu = run_child(stage, run, src.resolve(), out, config, which)
                    times[src].append(cpu)
                    print(
                        f"{stage:13s} {str(src):40s} run {k + 1}: {wall:7.2f} s wall {cpu:7.2f} CPU-s"
                    )
            for src, cpu in times.items():
                print(f"{stage:13s} {str(src):40s} median {statistics.median(cpu):7.2f} CPU-s")
            for i in range(1, len(args.src)):
                diff = largest_difference(
                    Path(tmp) / f"{stage}-0.npz", Path(tmp) / f"{stage}-{i}.npz"
                )
                print(
                    f"{stage:13s} outputs of {args.src[0]} and {args.src[i]}: largest |difference| {diff:.3g}"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
