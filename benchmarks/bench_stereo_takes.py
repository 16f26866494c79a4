"""Stereo reconstruction of the synthetic faces: accuracy against the truth, per parameter variant.

Renders the default rig's stereo takes (:func:`scan2morph.synth.make_stereo_take` with the
config's ``synthetic.stereo.rig``) of ``--subjects`` synthetic subjects and ``--labels``, and
reconstructs each with the config's ``stereo`` section and with each ``--variant`` (a
comma-separated list of ``key=value`` overrides of that section, values read as YAML). Prints per
variant, over the face region of every take (skin inside the landmark hull): coverage, depth RMS,
median and mean signed error (mm, + farther than the truth) against the exact ray-cast truth, and
the signed error binned by the curvature of the true surface (the Laplacian of the true range
image, mm per px squared; positive: convex towards the cameras), where a matching window that
does not follow the surface flattens it.

Usage::

    PYOPENGL_PLATFORM=osmesa .venv/bin/python benchmarks/bench_stereo_takes.py \\
        [--subjects 3] [--labels neutral car smile] \\
        [--variant rectify_interpolation=linear,patch_curvature=false [--variant ...]]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402

from scan2morph.evaluate import face_region, stereo_accuracy  # noqa: E402
from scan2morph.scan import reconstruct_stereo  # noqa: E402
from scan2morph.synth import LABEL_KIND, SEG_SKIN, make_stereo_take  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: Bins of the true range image's Laplacian, mm per px squared.
BINS = (-np.inf, -0.1, -0.03, 0.03, 0.1, np.inf)


def _variant(text: str) -> dict:
    """``key=value,key=value`` -> dict (values parsed as YAML)."""
    out = {}
    for item in filter(None, text.split(",")):
        key, _, value = item.partition("=")
        out[key.strip()] = yaml.safe_load(value)
    return out


def _laplacian(truth_xyz: np.ndarray) -> np.ndarray:
    """Laplacian of the true range image (Gaussian 1 px first), mm per px squared."""
    r = np.linalg.norm(truth_xyz, axis=2)
    r = np.where(np.isfinite(r), r, np.nanmedian(r)).astype(np.float32)
    return cv2.Laplacian(cv2.GaussianBlur(r, (0, 0), 1.0), cv2.CV_32F)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--subjects", type=int, default=3)
    ap.add_argument("--labels", nargs="+", default=["neutral", "car", "smile"])
    ap.add_argument("--variant", action="append", default=[], help="key=value,... overrides")
    args = ap.parse_args()
    config = yaml.safe_load(args.config.read_text())
    rig, seed = dict(config["synthetic"]["stereo"]["rig"]), int(config["synthetic"]["seed"])
    prefix = config["synthetic"]["prefix"]
    variants = {"config": {}} | {v: _variant(v) for v in args.variant}
    errors = {name: [] for name in variants}  # (signed error, laplacian) per face pixel
    stats = {name: [] for name in variants}
    seconds = {name: 0.0 for name in variants}
    for i in range(1, args.subjects + 1):
        subject = f"{prefix}{i:02d}"
        for label in args.labels:
            take = make_stereo_take(subject, label, LABEL_KIND[label], label, seed=seed, params=rig)
            truth = take["truth"]["xyz_true"]
            face = face_region(take["truth"]["segment"] == SEG_SKIN, take["truth"]["landmarks2d"])
            lap = _laplacian(truth)
            line = f"{subject} {label:>7}:"
            for name, over in variants.items():
                t0 = time.perf_counter()
                xyz, _ = reconstruct_stereo(
                    take["left"], take["right"], take["calib"], {**config["stereo"], **over}
                )
                seconds[name] += time.perf_counter() - t0
                acc = stereo_accuracy(xyz, truth, face)
                err = np.linalg.norm(xyz, axis=2) - np.linalg.norm(truth, axis=2)
                ok = face & np.isfinite(err)
                errors[name].append((err[ok], lap[ok]))
                stats[name].append(acc)
                line += f"  {acc['coverage']:.3f} {acc['depth_rms_mm']:.3f}"
            print(line + "  (coverage, RMS mm per variant)", flush=True)
    print(f"\n{len(stats['config'])} takes; face region; signed error + = farther than the truth")
    head = "".join(f" {f'[{lo:g},{hi:g})':>14}" for lo, hi in zip(BINS[:-1], BINS[1:], strict=True))
    print(f"{'variant':>48} {'cov':>6} {'rms':>6} {'median':>7} {'mean':>7} {'s/take':>6} |{head}")
    for name in variants:
        err = np.concatenate([e for e, _ in errors[name]])
        lap = np.concatenate([la for _, la in errors[name]])
        cov = np.mean([s["coverage"] for s in stats[name]])
        rms = float(np.sqrt(np.mean(err**2)))
        bins = ""
        for lo, hi in zip(BINS[:-1], BINS[1:], strict=True):
            sel = (lap >= lo) & (lap < hi)
            bins += f" {np.median(err[sel]):>+14.4f}" if sel.any() else f" {'-':>14}"
        print(
            f"{name[:48]:>48} {cov:>6.3f} {rms:>6.3f} {np.median(np.abs(err)):>7.3f} "
            f"{err.mean():>+7.4f} {seconds[name] / len(stats[name]):>6.2f} |{bins}"
        )
    print(
        "\ncov: mean share of the face pixels with a point; rms, median: |error| over all face "
        "pixels of all takes, mm; mean: signed; bins: median signed error by the Laplacian of "
        "the true range image (mm/px^2), mm."
    )


if __name__ == "__main__":
    main()
