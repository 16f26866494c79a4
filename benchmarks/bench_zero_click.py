"""Zero-click against clicked: the same synthetic scans with their landmark files and without.

Usage::

    .venv/bin/python benchmarks/bench_zero_click.py CLICKED_DIR DETECT_DIR

Each directory is a working directory in which the default cohort ran (``make run``), once as it
is (``synthetic.landmarks: clicked``: the generator's clicks, exact points + 0.5 px noise) and
once with ``synthetic.landmarks: detect`` (no landmark file: every take's landmarks detected).
To make them from a clone::

    make run                                     # in CLICKED_DIR
    make run CONFIG=benchmarks/zero_click.yaml   # in DETECT_DIR

It prints, per subject and take, the landmarks against the truth (median and 95th percentile
px, the 51 inner points and the jawline), the material relative error of each viseme's motion
and each expression's displacement with clicked and detected landmarks and their ratio, the
alignment against the truth, and which takes either run left out. Nothing is asserted: the
tables are the measurement.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def _accuracy(work: Path) -> dict[str, dict]:
    out = {}
    for path in sorted((work / "results").glob("*/accuracy.json")):
        out[path.parent.name] = json.loads(path.read_text())
    return out


def _material(entry: dict) -> float | None:
    for key in ("motion", "expression"):
        if key in entry:
            return entry[key].get("material_relative_error")
    return None


def _landmark_table(runs: dict[str, dict[str, dict]]) -> None:
    print(
        "\nLandmarks against the truth, px (640 x 480): median / p95 / inner-51 median / jaw median"
    )
    print(f"{'subject':9s} {'take':8s} {'modality':9s} {'clicked':>26s} {'detected':>26s}")
    by_modality: dict[str, list[list[float]]] = {}
    for subject, acc in runs["detect"].items():
        for take, entry in acc["takes"].items():
            cells = []
            for name in ("clicked", "detect"):
                lm = runs[name].get(subject, {}).get("takes", {}).get(take, {}).get("landmarks")
                cells.append(
                    "-"
                    if lm is None
                    else f"{lm['median_px']:5.2f} {lm['p95_px']:5.2f} "
                    f"{lm['inner_median_px']:5.2f} {lm['jaw_median_px']:5.2f}"
                )
            lm = entry.get("landmarks")
            if lm:
                by_modality.setdefault(entry["modality"], []).append(
                    [lm["median_px"], lm["p95_px"], lm["inner_median_px"], lm["jaw_median_px"]]
                )
            print(f"{subject:9s} {take:8s} {entry['modality']:9s} {cells[0]:>26s} {cells[1]:>26s}")
    print("\nDetected, per modality (median over takes): median / p95 / inner median / jaw median")
    for modality, rows in sorted(by_modality.items()):
        med = np.median(np.asarray(rows), axis=0)
        print(f"  {modality:8s} " + " ".join(f"{v:5.2f}" for v in med) + f"  ({len(rows)} takes)")


def _material_table(runs: dict[str, dict[str, dict]]) -> None:
    print("\nMaterial relative error (motion of visemes, displacement of expressions)")
    print(
        f"{'subject':9s} {'take':8s} {'clicked':>8s} {'detected':>9s} {'ratio':>6s} {'rot deg':>8s}"
    )
    ratios = []
    for subject, acc in runs["clicked"].items():
        other = runs["detect"].get(subject, {"takes": {}, "failed_takes": {}})
        for take, entry in acc["takes"].items():
            a = _material(entry)
            if a is None:
                continue
            b_entry = other["takes"].get(take)
            b = None if b_entry is None else _material(b_entry)
            rot = (
                "" if b_entry is None else f"{b_entry.get('align', {}).get('rotation_deg', 0):8.3f}"
            )
            ratio = "" if b is None else f"{b / a:6.2f}"
            if b is not None:
                ratios.append(b / a)
            shown = "left out" if b is None else f"{b:9.3f}"
            print(f"{subject:9s} {take:8s} {a:8.3f} {shown:>9s} {ratio:>6s} {rot}")
        for take, why in other.get("failed_takes", {}).items():
            print(f"{subject:9s} {take:8s} left out with detected landmarks: {why}")
    if ratios:
        r = np.asarray(ratios)
        print(
            f"\ndetected / clicked: median {np.median(r):.3f}, max {r.max():.3f}, "
            f"{int((r <= 1.10).sum())} of {len(r)} within 1.10x"
        )


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__)
        return 2
    runs = {"clicked": _accuracy(Path(argv[0])), "detect": _accuracy(Path(argv[1]))}
    if not runs["clicked"] or not runs["detect"]:
        print("no results/*/accuracy.json in one of the directories: run the cohort first")
        return 1
    _landmark_table(runs)
    _material_table(runs)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
