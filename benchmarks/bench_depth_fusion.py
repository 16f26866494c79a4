"""Several depth frames of an RGB-D take against one (issue #34, depth cameras).

Usage::

    .venv/bin/python benchmarks/bench_depth_fusion.py [--frames 1 2 4 8] [--takes neutral smile1]
    .venv/bin/python benchmarks/bench_depth_fusion.py --runs ONE_FRAME_DIR FUSED_DIR

The first form simulates takes of the default cohort's RGB-D subject (synth04, seed 2009, the
default 640 x 480 sensor) with 1, 2, 4 and 8 depth frames, the head moving between them
(``synthetic.rgbd.sensor.frame_motion_*``), and fuses them
(:func:`scan2morph.scan.fusion.fuse_depth_frames`). Per take and frame count it prints the depth
error of the face against the same pose rendered without noise (median and 90th percentile,
mm), the share of the face with data, how far the registration puts the face from the true
motion (median, mm) and the fusion's CPU time.

The second form compares two working directories of the default cohort, one run as it is and
one with ``synthetic.rgbd.sensor.frames`` above 1 (e.g. ``benchmarks/depth_fusion.yaml``), on
every RGB-D take: the alignment against the truth (degrees, mm), the mesh's RMS against the
true surface, the depth's RMS error and the material relative error of the motion. Nothing is asserted; the tables
are the measurement.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from scan2morph.io.rgbd import depth_points
from scan2morph.scan.fusion import fuse_depth_frames
from scan2morph.synth.cohort import default_takes
from scan2morph.synth.rgbd import make_rgbd_take

SUBJECT, SEED = "synth04", 2009
#: The noise-free render: no noise or flying pixels, 0.02 mm depth units (up to 1.3 m).
EXACT = {"noise_mm_at_1m": 0.0, "flying_fraction": 0.0, "depth_unit_mm": 0.02}


def _exact_depth(take: str, label: str, kind: str) -> np.ndarray:
    z = make_rgbd_take(SUBJECT, label, kind, take, SEED, EXACT)["depth"].astype(float) * 0.02
    return np.where((z > 0) & (z < 1000.0), z, np.nan)  # the head, not the wall


def _face_error(result: dict, fused, truth_z: np.ndarray) -> float:
    """Median over the frames 2.. of how far the found motion puts the face from the true one."""
    poses = result["truth"]["frame_poses"]
    ref = depth_points(np.nan_to_num(truth_z), result["intrinsics"].depth)
    ref = ref[np.isfinite(ref).all(axis=2)]
    errors = []
    for k in range(1, len(poses)):
        true = poses[0] @ np.linalg.inv(poses[k])
        p = (ref - true[:3, 3]) @ true[:3, :3]
        found = fused.transforms[k]
        errors.append(np.median(np.linalg.norm(p @ found[:3, :3].T + found[:3, 3] - ref, axis=1)))
    return float(np.median(errors))


def library_table(frame_counts: list[int], takes: list[str]) -> None:
    print(f"{'take':8s} {'frames':>6s} {'median mm':>10s} {'p90 mm':>8s} {'face kept':>10s} "
          f"{'registration mm':>16s} {'CPU s':>7s}")  # fmt: skip
    rows = {t: (k, label) for t, k, label in default_takes()}
    for take in takes:
        kind, label = rows[take]
        truth_z = _exact_depth(take, label, kind)
        face = np.isfinite(truth_z)
        for n in frame_counts:
            result = make_rgbd_take(SUBJECT, label, kind, take, SEED, {"frames": n})
            intr = result["intrinsics"]
            depth = result["depth"] if n > 1 else [result["depth"]]
            frames = [d.astype(float) * intr.depth_scale_mm for d in depth]
            start = time.process_time()
            fused = fuse_depth_frames(frames, intr.depth, [f"frame{k}" for k in range(n)])
            cpu = time.process_time() - start
            e = np.abs(fused.depth_mm - truth_z)[face]
            kept = np.isfinite(e)
            reg = _face_error(result, fused, truth_z) if n > 1 else 0.0
            print(
                f"{take:8s} {n:6d} {np.median(e[kept]):10.3f} {np.percentile(e[kept], 90):8.3f} "
                f"{kept.mean():10.3f} {reg:16.3f} {cpu:7.2f}"
            )


def _rgbd_takes(work: Path) -> dict[str, dict]:
    out = {}
    for path in sorted((work / "results").glob("*/accuracy.json")):
        acc = json.loads(path.read_text())
        for take, entry in acc["takes"].items():
            if entry.get("modality") == "rgbd":
                out[f"{path.parent.name}/{take}"] = entry
    return out


def _numbers(entry: dict) -> list[float]:
    align = entry.get("align", {})
    motion = entry.get("motion") or entry.get("expression") or {}
    return [
        align.get("rotation_deg", np.nan),
        align.get("translation_mm", np.nan),
        entry.get("rgbd", {}).get("depth_rms_mm", np.nan),
        entry.get("mesh", {}).get("rms_mm", np.nan),
        motion.get("material_relative_error", np.nan),
    ]


def runs_table(one: Path, fused: Path) -> None:
    a, b = _rgbd_takes(one), _rgbd_takes(fused)
    print(
        "RGB-D takes, one frame -> fused: alignment degrees, mm; depth RMS mm; mesh RMS mm; "
        "material relative error"
    )
    for key in sorted(set(a) | set(b)):
        x = _numbers(a.get(key, {}))
        y = _numbers(b.get(key, {}))
        cells = "  ".join(f"{u:6.3f} -> {v:6.3f}" for u, v in zip(x, y, strict=True))
        print(f"{key:18s} {cells}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--takes", nargs="+", default=["neutral", "car", "smile1", "sad1"])
    parser.add_argument("--runs", type=Path, nargs=2, metavar=("ONE_FRAME_DIR", "FUSED_DIR"))
    args = parser.parse_args()
    if args.runs:
        runs_table(*args.runs)
    else:
        library_table(args.frames, args.takes)


if __name__ == "__main__":
    main()
