"""Zero-click on the real head when the head turns between the neutral and its takes.

Usage::

    .venv/bin/python benchmarks/bench_turned_takes.py [--work DIR] [--seed 7] [--cores 2]
        [--yaw 0 8] [--turned-view-deg 5] [--repo DIR]

The real head of the real-data tests (``../shared/data``, CC BY 3.0; tests/support/real_head.py)
is written as a user's range scans (tests/support/turned_takes.py): a neutral, a jaw drop
(``car1``, a viseme) and a smile (``smile1``, an expression), moving the vertices and so the
texture with them (the skin's material motion is known at every point), each seen by a fixed
640 x 480 range scanner 900 mm away (about 1.9 px per mm at the face; 0.15 mm of noise along
the rays, 1.5 grey levels in the colour). The neutral is seen from yaw 4, pitch 2 degrees; per
variant its takes are seen from the same view (``same``, ``--yaw 0``) or turned (``yaw8``: the
head turned 8 degrees between the neutral and its takes, ``--yaw 8``). Each variant is two
subjects: one gives the hand annotation moved with the skin as landmark files (``clicked``),
the other leaves the landmarks column empty (``detected``: the zero-click path). The workflow
runs on the sheet with the default config, as ``make run CONFIG=...`` would.

``--turned-view-deg 5`` sets ``landmarks.turned_view_deg`` (off by default: a doubtful detection
turned more than that follows its neutral's points the whole way, docs/landmarks.md).
``--repo DIR`` runs another checkout's code (its ``src`` and its Snakefile and
``config/config.yaml``) on the same scans, e.g. a branch's worktree holding a fix.

It prints, per subject and take, the landmarks' source, the alignment's rotation error
(degrees), the true motion's RMS (mm), the material error (RMS of the measured displacement's
error over the true motion's RMS, over the valid template vertices), the take job's wall time,
and whether the detection was found doubtful; then the material errors side by side, and the
workflow's wall time. Nothing is asserted: the table is the measurement.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _use_repo(repo: Path) -> str:
    """Import the library from ``repo``'s ``src``, in this process and in the workflow's jobs
    (``PYTHONPATH``); the folder it was imported from."""
    src = str(repo / "src")
    sys.path.insert(0, src)
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, (src, os.environ.get("PYTHONPATH"))))
    import scan2morph

    where = Path(scan2morph.__file__).resolve().parent
    if not where.is_relative_to(Path(src).resolve()):
        raise SystemExit(f"scan2morph was imported from {where} before {src} could be used")
    return str(where)


def _job_seconds(path: Path) -> float:
    """A rule's benchmark file's wall time, s (NaN when the job did not run)."""
    if not path.is_file():
        return float("nan")
    header, values = path.read_text().splitlines()[:2]
    return float(values.split("\t")[header.split("\t").index("s")])


def _print_code(store: Path) -> None:
    """The code a store was made with (the library's digest and its checkout's commit)."""
    from scan2morph.store import read_attrs

    attrs = read_attrs(store)
    dirty = " with uncommitted changes" if attrs.get("git_dirty") else ""
    print(f"code {attrs.get('code_sha256', '?')[:12]}, commit {attrs.get('git_commit')}{dirty}")


def _print_takes(work: Path, results: dict[str, dict]) -> None:
    """The per-subject, per-take table."""
    print(
        f"{'subject':16s} {'take':7s} {'landmarks':9s} {'rot deg':>8s} {'motion mm':>10s} "
        f"{'material':>9s} {'vertices':>9s} {'take s':>7s}  doubtful"
    )
    for subject, takes in results.items():
        for take, r in takes.items():
            seconds = _job_seconds(work / "benchmarks" / "takes" / subject / f"{take}.tsv")
            if "left_out" in r:
                print(f"{subject:16s} {take:7s} left out: {r['left_out']}")
                continue
            print(
                f"{subject:16s} {take:7s} {r['landmark_source']:9s} {r['rotation_deg']:8.3f} "
                f"{r['motion_rms_mm']:10.3f} {r['material_relative_error']:9.3f} "
                f"{r['vertices']:9d} {seconds:7.0f}  {'yes' if r['doubtful'] else '-'}"
            )


def _material(take: dict) -> str:
    """A take's material error as a table cell."""
    return "left out" if "left_out" in take else f"{take['material_relative_error']:.3f}"


def _print_summary(results: dict[str, dict], turns, sources) -> None:
    """The material errors: a row per variant and take, a column per landmark source."""
    from tests.support.turned_takes import variant_name

    print(f"\nmaterial error\n{'variant':8s} {'take':7s}" + "".join(f" {s:>9s}" for s in sources))
    takes = next(iter(results.values())).keys()
    for variant in map(variant_name, turns):
        for take in takes:
            cells = (results[f"{variant}_{s}"][take] for s in sources)
            print(f"{variant:8s} {take:7s}" + "".join(f" {_material(c):>9s}" for c in cells))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/bench_turned_takes"))
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument(
        "--yaw", type=float, nargs="+", default=[0.0, 8.0],
        help="the takes' turns from the neutral's view, degrees (one variant each)",
    )  # fmt: skip
    parser.add_argument(
        "--turned-view-deg", type=float, default=None,
        help="landmarks.turned_view_deg for the run (default: the config's, off)",
    )  # fmt: skip
    parser.add_argument(
        "--repo", type=Path, default=ROOT,
        help="the checkout whose library and Snakefile run (default: this one)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    library = _use_repo(args.repo.resolve())

    from tests.support import workflow_api
    from tests.support.lps_landmarks import load_real_head
    from tests.support.real_head import GLB
    from tests.support.turned_takes import SOURCES, evaluate, subjects, write_takes

    if not GLB.is_file():
        print(f"the real head is absent: {GLB}")
        return 1
    args.work.mkdir(parents=True, exist_ok=True)
    head = load_real_head()
    poses = write_takes(head, args.work, args.seed, args.yaw)
    names = subjects(args.yaw)
    if args.turned_view_deg is not None:  # a doubtful take turned more follows its neutral's points
        config = yaml.safe_load((args.work / "turned.yaml").read_text())
        config["landmarks"] = {"turned_view_deg": args.turned_view_deg}
        (args.work / "turned.yaml").write_text(yaml.safe_dump(config))
    targets = [f"results/{s}/{s}.h5" for s in names]
    print(f"library {library}, Snakefile {args.repo.resolve() / 'Snakefile'}")
    t0 = time.perf_counter()
    done = workflow_api.run_workflow(
        args.work, args.work / "turned.yaml", targets, cores=args.cores, repo=args.repo.resolve()
    )
    wall = time.perf_counter() - t0
    print(f"\nworkflow {'finished' if done else 'FAILED'} in {wall:.0f} s ({args.work})")
    results = {}
    for s in names:
        store = args.work / "results" / s / f"{s}.h5"
        if store.is_file():
            results[s] = evaluate(head, args.work, s, poses)
        else:
            print(f"{s}: no store ({store})")
    if results:
        _print_code(args.work / "results" / names[0] / f"{names[0]}.h5")
        _print_takes(args.work, results)
    if len(results) == len(names):
        _print_summary(results, args.yaw, SOURCES)
    out = {"library": library, "wall_s": wall, "takes": results}
    (args.work / "bench_turned_takes.json").write_text(json.dumps(out, indent=1))
    return 0 if done else 1


if __name__ == "__main__":
    sys.exit(main())
