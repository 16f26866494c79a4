"""Zero-click landmarks against the truth: candidates x modalities, and the real head.

Candidates (scan2morph.landmarks):
* ``geometry``: the training mean shape placed by the geometry alone (the nose tip found on the
  range data, the metric scale of the grid), no image or shape fitting;
* ``cascade``: the trained cascade (:func:`scan2morph.landmarks.detect`);
* ``cascade+refine``: the cascade, then the geometric refinement on the 3D surface.

Takes: every take of the default synthetic cohort (config/config.yaml: seed 2009, held out from
training) after the ingest and repair stages, per modality; and range renders of the real head
(Lee Perry-Smith, ``../shared/data``) in several poses against our own hand annotation
(tests/support/lps_landmarks.py). Errors in px on the take's 640 x 480 grid: median and 95th
percentile of the 51 inner points and of the 17 jawline points; time per take (detection with
the model already loaded). Also: whether the generator's jawline truth lies on the face's
silhouette in open-mouth visemes.

Run: ``PYOPENGL_PLATFORM=osmesa .venv/bin/python benchmarks/bench_landmarks.py [--cache F]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
from scan2morph.landmarks.canonical import canonical  # noqa: E402
from scan2morph.landmarks.detect import cached_model, detect  # noqa: E402
from scan2morph.landmarks.face import find_face  # noqa: E402
from tests.support.landmark_takes import GridTake, cohort_takes  # noqa: E402


def geometry_only(color, xyz, source):
    """The mean shape placed from the geometry alone (nose tip, scale)."""
    can = canonical(find_face(xyz, source), color)
    return can.to_image(cached_model().init)


def cascade(color, xyz, source):
    return detect(color, xyz, source).points


CANDIDATES = {"geometry": geometry_only, "cascade": cascade}


def load_takes(cache: Path | None) -> list[GridTake]:
    """Every take of the default cohort on its grid (from ``cache`` when it exists)."""
    if cache is not None and cache.is_file():
        with np.load(cache, allow_pickle=False) as z:
            meta = [str(m).split("|") for m in z["meta"]]
            return [GridTake(*m, z[f"c{i}"], z[f"x{i}"], z[f"t{i}"]) for i, m in enumerate(meta)]
    with tempfile.TemporaryDirectory() as tmp:
        takes = cohort_takes(Path(tmp))
    if cache is not None:
        arrays = {"meta": np.array([f"{t.subject}|{t.take}|{t.label}|{t.modality}" for t in takes])}
        for i, t in enumerate(takes):
            arrays |= {f"c{i}": t.color, f"x{i}": t.xyz, f"t{i}": t.truth}
        np.savez(cache, **arrays)
    return takes


def _row(name: str, errs: list[np.ndarray], times: list[float]) -> str:
    e = np.stack(errs)
    inner, jaw = e[:, 17:].ravel(), e[:, :17].ravel()
    cells = [
        np.median(e),
        np.percentile(e, 95),
        np.median(inner),
        np.percentile(inner, 95),
        np.median(jaw),
        np.percentile(jaw, 95),
        np.max(e),
    ]
    vals = " ".join(f"{v:7.2f}" for v in cells)
    return f"{name:<28} {len(errs):4d} {vals} {1000 * np.median(times):8.0f}"


HEADER = (
    f"{'candidate / takes':<28} {'n':>4} {'med':>7} {'p95':>7} {'in-med':>7} {'in-p95':>7} "
    f"{'jaw-med':>7} {'jaw-p95':>7} {'max':>7} {'ms/take':>8}"
)


def evaluate(takes: list[GridTake], groups) -> None:
    """Print one row per candidate and group of takes."""
    print(HEADER)
    for name, fn in CANDIDATES.items():
        results = {}
        for t in takes:
            t0 = time.perf_counter()
            pts = fn(t.color, t.xyz, f"{t.subject}/{t.take}")
            dt = time.perf_counter() - t0
            results[(t.subject, t.take)] = (np.linalg.norm(pts - t.truth, axis=1), dt)
        for gname, pick in groups:
            sel = [results[(t.subject, t.take)] for t in takes if pick(t)]
            if sel:
                print(_row(f"{name} {gname}", [s[0] for s in sel], [s[1] for s in sel]))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cache", type=Path, default=None, help="npz of the cohort's grids")
    args = parser.parse_args()
    cached_model()
    takes = load_takes(args.cache)
    groups = [(m, lambda t, m=m: t.modality == m) for m in ("range", "stereo", "mesh", "rgbd")]
    groups.append(("all", lambda t: True))
    evaluate(takes, groups)


if __name__ == "__main__":
    main()
