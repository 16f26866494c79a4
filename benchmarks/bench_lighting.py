"""The real head's smile with its colour images at another exposure than its neutral's.

Usage::

    .venv/bin/python benchmarks/bench_lighting.py [--work DIR] [--seed 7] [--cores 2]
        [--exposures same dark_smile dark bright bright_smile]

The real head (``../shared/data``, CC BY 3.0) written as a user's range and RGB-D takes with
their landmark files (``tests/support/real_user.py``, as ``benchmarks/bench_real_user.py`` writes
them), then, per exposure, each take's colour image scaled by a gain (rounded, clipped to 8
bits) and the workflow run on the sheet with the default config:

- ``same``: as written;
- ``dark_smile``: the smile's image at 0.3 of its brightness, the neutral's as written;
- ``dark``: both at 0.3;
- ``bright``: both at 2 (the face white: 99% of its pixels clipped at 255);
- ``bright_smile``: the smile's at 2, the neutral's as written.

It prints, per exposure and scan, the share of the smile's face clipped, the smile's material
error (RMS error of its displacement over its RMS motion) and its warnings. Nothing is asserted:
the table is the measurement.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.support.lps_landmarks import load_real_head  # noqa: E402
from tests.support.real_head import GLB  # noqa: E402
from tests.support.real_user import evaluate, write_scans  # noqa: E402
from tests.support.workflow_api import run_workflow  # noqa: E402

#: The gains of the neutral's and the smile's colour images, per exposure.
EXPOSURES = {
    "same": (1.0, 1.0),
    "dark_smile": (1.0, 0.3),
    "dark": (0.3, 0.3),
    "bright": (2.0, 2.0),
    "bright_smile": (1.0, 2.0),
}
#: The scans measured (``tests/support/real_user.py``'s subjects with landmark files).
SUBJECTS = ("range_clicked", "rgbd_clicked")
#: Each scan's colour image, as ``write_scans`` names it.
COLOR = {"range": "range.png", "rgbd": "color.png"}


def expose(base: Path, work: Path, gains: tuple[float, float]) -> None:
    """A copy of the scans in ``base`` with the neutral's and the smile's colour images times
    ``gains``, its sheet holding :data:`SUBJECTS` only, and its config."""
    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(base, work)
    for take, gain in zip(("neutral", "smile"), gains, strict=True):
        for name in COLOR.values():
            path = work / "scans" / take / name
            image = cv2.imread(str(path)).astype(np.float64)
            cv2.imwrite(str(path), np.clip(np.rint(gain * image), 0, 255).astype(np.uint8))
    rows = (work / "subjects.tsv").read_text().splitlines()
    kept = [rows[0]] + [r for r in rows[1:] if r.split("\t")[0] in SUBJECTS]
    (work / "subjects.tsv").write_text("\n".join(kept) + "\n")
    config = yaml.safe_load((work / "real.yaml").read_text())
    (work / "real.yaml").write_text(
        yaml.safe_dump(config | {"subjects": str(work / "subjects.tsv")})
    )


def clipped(work: Path, subject: str) -> float:
    """Share of the smile's face (its repaired range image's points within its landmarks)
    clipped in its colour."""
    from scan2morph.stages.quality import take_clipped_share
    from scan2morph.store import read_part

    takes = work / "results" / subject / "takes" / "smile"
    return take_clipped_share(
        read_part(takes / "repair.h5") | read_part(takes / "landmarks.h5"), "smile"
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/bench_lighting"))
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--exposures", nargs="+", default=list(EXPOSURES), choices=EXPOSURES)
    args = parser.parse_args(argv)
    if not GLB.is_file():
        print(f"the real head is absent: {GLB}")
        return 1
    head = load_real_head()
    base = args.work / "scans"
    base.mkdir(parents=True, exist_ok=True)
    poses = write_scans(head, base, args.seed, ("range", "rgbd"))
    out, failed = {}, False
    for exposure in args.exposures:
        work = args.work / exposure
        expose(base, work, EXPOSURES[exposure])
        targets = [f"results/{s}/{s}.h5" for s in SUBJECTS]
        failed |= not run_workflow(work, work / "real.yaml", targets, cores=args.cores)
        for subject in SUBJECTS:
            r = evaluate(head, work, subject, poses)
            r["clipped_share"] = clipped(work, subject)
            out[f"{exposure}/{subject}"] = r
    print(f"\n{'exposure':13s} {'subject':14s} {'clipped':>8s} {'material':>9s}  warnings")
    for key, r in out.items():
        exposure, subject = key.split("/")
        error = "left out" if "left_out" in r else f"{r['material_relative_error']:9.3f}"
        said = "; ".join(w[:70] for w in r.get("warnings", [])) or "none"
        print(f"{exposure:13s} {subject:14s} {r['clipped_share']:8.3f} {error:>9s}  {said}")
    (args.work / "bench_lighting.json").write_text(json.dumps(out, indent=1))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
