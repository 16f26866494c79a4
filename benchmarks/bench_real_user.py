"""The real head through the user's path: mesh, range, RGB-D and stereo scans, clicked and not.

Usage::

    .venv/bin/python benchmarks/bench_real_user.py [--work DIR] [--seed 7] [--cores 2]

The real head of the real-data tests (``../shared/data``, CC BY 3.0; tests/support/real_head.py)
is written as a user's scans: a neutral and a smiling take (the real-data tests' smile, the cheeks
5 mm up and out and the mouth corners 6 mm, moving the vertices and so the texture with them: the
skin's material motion is known at every point), each an OBJ with its colour map (MTL + image) in
a scanner frame of its own (a seeded rotation of a few degrees and a few mm), and the hand
annotation's 68 points moved with them (tests/support/lps_landmarks.py) as landmark files; each
OBJ also scanned as a range scan and as an RGB-D take, and the head seen by the real-data tests'
stereo rig (tests/support/real_user.py), whose speckle is projected from the rig and does not move
with the skin: once with the left image as the takes' colour (``stereo``), once with the left
camera's texture shot, the projector off (``stereo-shot``, the sheet's ``color``). Per scan
one subject's rows give the landmark files (clicked), another's leave them out (detected); the
workflow runs on the sheet with the default config, as ``make run CONFIG=...`` would.

It prints, per subject, the alignment of the smile against the truth (degrees, mm), the
expression displacement's material error (RMS error over RMS motion over the valid template
vertices; also along the neutral's normals and across them), the detected landmarks' warnings,
and the wall time. Nothing is asserted: the table is the measurement.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.lps_landmarks import load_real_head  # noqa: E402
from tests.support.real_head import GLB  # noqa: E402
from tests.support.real_user import SUBJECTS, evaluate, write_scans  # noqa: E402
from tests.support.workflow_api import run_workflow  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/bench_real_user"))
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--cores", type=int, default=2)
    args = parser.parse_args(argv)
    if not GLB.is_file():
        print(f"the real head is absent: {GLB}")
        return 1
    args.work.mkdir(parents=True, exist_ok=True)
    head = load_real_head()
    poses = write_scans(head, args.work, args.seed)
    t0 = time.perf_counter()
    targets = [f"results/{s}/{s}.h5" for s in SUBJECTS]
    done = run_workflow(args.work, args.work / "real.yaml", targets, cores=args.cores)
    wall = time.perf_counter() - t0
    print(f"\nworkflow {'finished' if done else 'FAILED'} in {wall:.0f} s ({args.work})")
    print(
        f"{'subject':19s} {'rot deg':>8s} {'trans mm':>9s} {'motion mm':>10s} {'material':>9s} "
        f"{'normal mm':>10s} {'tangent mm':>11s} {'vertices':>9s}"
    )
    out = {}
    for subject in SUBJECTS:
        r = out[subject] = evaluate(head, args.work, subject, poses)
        if "left_out" in r:
            print(f"{subject:19s} the smile was left out: {r['left_out']}")
            continue
        print(
            f"{subject:19s} {r['rotation_deg']:8.3f} {r['translation_mm']:9.3f} "
            f"{r['motion_rms_mm']:10.3f} {r['material_relative_error']:9.3f} "
            f"{r['normal_mm']:10.3f} {r['tangential_mm']:11.3f} {r['vertices']:9d}"
        )
        for w in r["warnings"]:
            print(f"    warning: {w}")
    (args.work / "bench_real_user.json").write_text(json.dumps(out, indent=1))
    return 0 if done else 1


if __name__ == "__main__":
    sys.exit(main())
