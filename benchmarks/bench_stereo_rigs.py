"""Stereo reconstruction with the default config across rigs: working distance, baseline, size.

Renders a synthetic stereo take of a face (:func:`scan2morph.synth.make_stereo_take`) per rig,
from 0.4 to 2 m working distance, 60-300 mm baseline, 640x480 to 2448x2048 images, parallel
to strongly toed-in cameras, barrel and pincushion distortion, and reconstructs it with the
config's ``stereo`` section as it is (the depth range derived from the pair). The focal length
frames the face alike at every distance (``fill`` of the default rig's framing). Prints per
rig the depth range used, the coverage of the face region and the depth error against the
exact ray-cast truth, and the time of the reconstruction.

Usage::

    PYOPENGL_PLATFORM=osmesa .venv/bin/python benchmarks/bench_stereo_rigs.py [--quick]
        [--fixed 500 900]

``--quick`` skips the rigs above 1280 px; ``--fixed NEAR FAR`` also runs every rig with that
fixed depth range (e.g. the former default, 500-900 mm) for comparison (slow on the large
far rigs: that range spans thousands of px of disparity there); ``--only I ...`` runs those
rows of ``RIGS``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from scan2morph.errors import InputError  # noqa: E402
from scan2morph.evaluate import face_region, stereo_accuracy  # noqa: E402
from scan2morph.scan import reconstruct_stereo  # noqa: E402
from scan2morph.synth import SEG_SKIN, make_stereo_take  # noqa: E402

REPO = Path(__file__).resolve().parents[1]

#: distance (mm), baseline (mm), width, height, toe-in (deg), k1, fill of the default framing
RIGS = (
    (400, 60, 640, 480, 4.3, -0.05, 0.75),  # near, short baseline
    (650, 120, 640, 480, 4.0, -0.05, 1.0),  # the default synthetic rig
    (1000, 120, 1280, 960, 3.4, -0.05, 0.75),  # issue 14's rig
    (1500, 200, 1600, 1200, 0.0, 0.0, 0.75),  # parallel cameras, no distortion
    (2000, 300, 2448, 2048, 4.3, -0.1, 0.75),  # far, long baseline, large images
    (400, 200, 1024, 768, 14.0, 0.1, 0.75),  # near, strong toe-in, pincushion
    (2000, 60, 640, 480, 0.9, -0.2, 0.75),  # far, short baseline, strong barrel
    (800, 300, 1280, 1024, 10.6, -0.1, 0.6),  # long baseline, wide framing
)


def _rig(distance, baseline, width, height, toe, k1, fill) -> dict:
    """Parameters of :func:`make_stereo_take` for one rig (the default rig's other keys)."""
    focal = 1300.0 * (width / 640.0) * (distance / 650.0) * fill
    return {
        "width": width,
        "height": height,
        "focal_px": round(focal, 1),
        "distance_mm": float(distance),
        "baseline_mm": float(baseline),
        "toe_in_deg": float(toe),
        "k1": float(k1),
        # render time grows with the square of this: 1 above 1280 px
        "supersample": 3 if width <= 1280 else 1,
    }


def _measure(take: dict, face: np.ndarray, params: dict) -> tuple[dict, dict, float] | str:
    """Accuracy over the face, the report and the time (s); the error message on failure."""
    t0 = time.perf_counter()
    try:
        xyz, report = reconstruct_stereo(take["left"], take["right"], take["calib"], params)
    except InputError as err:
        return str(err.problem)[:60]
    seconds = time.perf_counter() - t0
    return stereo_accuracy(xyz, take["truth"]["xyz_true"], face), report, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only rigs up to 1280 px wide")
    parser.add_argument("--fixed", type=float, nargs=2, metavar=("NEAR", "FAR"))
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--only", type=int, nargs="+", metavar="I", help="rows of RIGS, 0-based")
    args = parser.parse_args()
    stereo = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["stereo"]

    head = (
        f"{'dist':>5} {'base':>5} {'size':>10} {'toe':>5} {'k1':>6} {'f px':>7} "
        f"{'face z':>10} {'derived range':>14} {'s':>3} {'ndisp':>6} {'cov':>6} {'rms':>6} "
        f"{'median':>7} {'time':>6}"
    )
    if args.fixed:
        head += f" | fixed {args.fixed[0]:g}-{args.fixed[1]:g}: cov, rms"
    print(head)
    print(" mm    mm     px        deg           px        mm          mm" + 36 * " " + "mm  mm  s")
    for i, rig in enumerate(RIGS):
        if (args.quick and rig[2] > 1280) or (args.only and i not in args.only):
            continue
        params = _rig(*rig)
        take = make_stereo_take("s1", "car", "viseme", "car", seed=args.seed, params=params)
        truth = take["truth"]
        face = face_region(truth["segment"] == SEG_SKIN, truth["landmarks2d"])
        z = truth["xyz_true"][face][:, 2]
        z_text = f"{np.percentile(z, 0):.0f}-{np.percentile(z, 100):.0f}"
        out = _measure(take, face, stereo)
        line = (
            f"{rig[0]:>5} {rig[1]:>5} {f'{rig[2]}x{rig[3]}':>10} {rig[4]:>5.1f} {rig[5]:>6.2f} "
            f"{params['focal_px']:>7.0f} {z_text:>10} "
        )
        if isinstance(out, str):
            line += f"FAILED: {out}"
        else:
            acc, report, seconds = out
            near, far = report["depth_range_mm"]
            line += (
                f"{f'{near:.0f}-{far:.0f}':>14} {report['coarse_scale']:>3} "
                f"{report['numDisparities']:>6} {acc['coverage']:>6.3f} "
                f"{acc['depth_rms_mm']:>6.3f} {acc['depth_median_mm']:>7.3f} {seconds:>6.1f}"
            )
        if args.fixed:
            fixed = {**stereo, "min_depth_mm": args.fixed[0], "max_depth_mm": args.fixed[1]}
            res = _measure(take, face, fixed)
            line += " | " + (
                res
                if isinstance(res, str)
                else f"{res[0]['coverage']:.3f}, {res[0]['depth_rms_mm']:.3f}"
            )
        print(line, flush=True)
    print(
        "\nface z: depth range of the face region's truth, mm; s: coarse pyramid factor; "
        "ndisp: numDisparities of the fine pass; cov: fraction of the face region (skin inside "
        "the landmark hull) with a point; rms, median: 3D error against the truth, mm; time: "
        "reconstruct_stereo, s."
    )


if __name__ == "__main__":
    main()
