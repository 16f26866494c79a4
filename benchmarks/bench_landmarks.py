"""Zero-click landmarks against the truth: candidates x modalities, and the real head.

Candidates (scan2morph.landmarks):
* ``geometry``: the training mean shape placed by the geometry alone (the nose tip found on the
  range data, the metric scale of the grid), no image or shape fitting;
* ``cascade-1``: the trained cascade from the mean shape alone;
* ``cascade-7``: the cascade from 7 starts around the global stage's shape, on the canonical
  frame only;
* ``cascade-7+mirror``: the same on the frame and on its mirror image (the detector,
  :func:`scan2morph.landmarks.detect`);
* ``+lips (doubtful)``: the detector, and a doubtful detection's mouth (median confidence below
  the landmarks stage's ``min_confidence``) placed on the lips' colour edge
  (:func:`scan2morph.landmarks.fit_lips`);
* ``+lips+brows (doubtful)``: and its brows on the eyebrows' dark bands
  (:func:`scan2morph.landmarks.fit_brows`);
* ``+lips+brows+chin (doubtful)``: and its chin, with the jawline, on the face's outline below
  the mouth (:func:`scan2morph.landmarks.fit_chin`), as the landmarks stage places them.

Takes: every take of the default synthetic cohort (config/config.yaml: seed 2009, held out from
training) after the ingest and repair stages, per modality; and range renders of the real head
(Lee Perry-Smith, ``../shared/data``) in several poses against our own hand annotation
(tests/support/lps_landmarks.py). Errors in px on the take's 640 x 480 grid: median and 95th
percentile of the 51 inner points and of the 17 jawline points; CPU time per take (detection with
the model already loaded). Also: whether the generator's jawline truth lies on the face's
silhouette in open-mouth visemes.

The second pass (the landmarks stage's :func:`~scan2morph.stages.landmarks.second_pass`, each
subject's takes against its detected neutral) step by step: the detector alone, its stable
points carried from the neutral, and its other points tracked from the neutral by image
correlation; per modality against the truth, the takes' error relative to their neutral's
(what a motion sees: ``(take - truth) - (neutral - truth)`` per point, px) and how well the
stable points agree with the neutral's after the rigid alignment.

Per region (the detector, median px): jawline, brows, nose, eyes and mouth of each group.

Run: ``PYOPENGL_PLATFORM=osmesa .venv/bin/python benchmarks/bench_landmarks.py [--cache F]
[--model M]`` (``--model``: a trained cascade instead of the committed one, e.g. a retrain's).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
from scan2morph.align.carry import carry_stable  # noqa: E402
from scan2morph.align.rigid import transform_points  # noqa: E402
from scan2morph.landmarks.canonical import canonical  # noqa: E402
from scan2morph.landmarks.cascade import run  # noqa: E402
from scan2morph.landmarks.detect import cached_model, detect, ensemble_shapes  # noqa: E402
from scan2morph.landmarks.face import find_face  # noqa: E402
from scan2morph.scan.view import shaded_image  # noqa: E402
from scan2morph.stages.landmarks import (  # noqa: E402
    DETECTED,
    Landmarks,
    Params,
    features_placed,
    second_pass,
)
from scan2morph.stages.part import Take  # noqa: E402
from scan2morph.store import paths  # noqa: E402
from scan2morph.template.sample import range_pixels, sample_range  # noqa: E402
from tests.support.landmark_takes import GridTake, cohort_takes  # noqa: E402


def geometry_only(color, xyz, source):
    """The mean shape placed from the geometry alone (nose tip, scale)."""
    can = canonical(find_face(xyz, source), color)
    return can.to_image(cached_model().init)


def cascade_single(color, xyz, source):
    """The cascade from the mean shape alone (no ensemble)."""
    model = cached_model()
    can = canonical(find_face(xyz, source), color)
    return can.to_image(run(model, can.channels, model.init))


def cascade_frame_only(color, xyz, source):
    """The cascade from the 7 starts on the canonical frame only (not its mirror image)."""
    can = canonical(find_face(xyz, source), color)
    return can.to_image(np.median(ensemble_shapes(cached_model(), can.channels), axis=0))


def cascade(color, xyz, source):
    return detect(color, xyz, source).points


def _features(color, xyz, source, **steps):
    """The detector and the stage's rule for a doubtful detection's features: ``steps`` the
    :class:`~scan2morph.stages.landmarks.Params` switches of the steps left out."""
    found = detect(color, xyz, source)
    detected = Landmarks(found.points, DETECTED, found.confidence)
    return features_placed(detected, (xyz, color), Params(**steps))[0].points


def cascade_lips(color, xyz, source):
    """The detector, a doubtful detection's mouth on the lips' colour edge."""
    return _features(color, xyz, source, brows_from_colour=False, chin_from_shape=False)


def cascade_lips_brows(color, xyz, source):
    """The detector, a doubtful detection's mouth and brows placed."""
    return _features(color, xyz, source, chin_from_shape=False)


def cascade_features(color, xyz, source):
    """The detector, a doubtful detection's mouth, brows and chin placed (the stage's rule)."""
    return _features(color, xyz, source)


CANDIDATES = {
    "geometry": geometry_only,
    "cascade-1": cascade_single,
    "cascade-7": cascade_frame_only,
    "cascade-7+mirror": cascade,
    "+lips (doubtful)": cascade_lips,
    "+lips+brows (doubtful)": cascade_lips_brows,
    "+lips+brows+chin (doubtful)": cascade_features,
}
#: The candidates whose median per region is printed.
REGION_CANDIDATES = (
    "cascade-7+mirror",
    "+lips (doubtful)",
    "+lips+brows (doubtful)",
    "+lips+brows+chin (doubtful)",
)


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
    f"{'jaw-med':>7} {'jaw-p95':>7} {'max':>7} {'cpu ms':>8}"
)


#: iBUG-68 regions (0-based point ranges) of the per-region rows.
REGIONS = {
    "jaw": slice(0, 17),
    "brows": slice(17, 27),
    "nose": slice(27, 36),
    "eyes": slice(36, 48),
    "mouth": slice(48, 68),
}


def _region_row(name: str, errs: list[np.ndarray]) -> str:
    e = np.stack(errs)
    return f"{name:<28} " + " ".join(f"{k} {np.median(e[:, s]):5.2f}" for k, s in REGIONS.items())


def evaluate(takes, groups) -> None:
    """Print one row per candidate and group of takes (objects with ``color``, ``xyz``,
    ``truth`` and ``name``), then the median per region of :data:`REGION_CANDIDATES`."""
    print(HEADER)
    regions = []
    for name, fn in CANDIDATES.items():
        results = []
        for t in takes:
            t0 = time.process_time()  # CPU time: the machine may be shared
            pts = fn(t.color, t.xyz, t.name)
            dt = time.process_time() - t0
            results.append((np.linalg.norm(pts - t.truth, axis=1), dt))
        for gname, pick in groups:
            sel = [r for t, r in zip(takes, results, strict=True) if pick(t)]
            if sel:
                print(_row(f"{name} {gname}", [s[0] for s in sel], [s[1] for s in sel]))
                if name in REGION_CANDIDATES:
                    regions.append(_region_row(f"{name} {gname}", [s[0] for s in sel]))
    print("median per region (px)")
    print("\n".join(regions))


#: Poses (yaw, pitch; degrees) of the real head's renders.
REAL_POSES = [(0, 0), (10, 5), (-10, -5), (15, 0), (-15, 0), (0, 10), (0, -10), (20, 5)]


@dataclass(frozen=True)
class _Named:
    name: str
    color: np.ndarray
    xyz: np.ndarray
    truth: np.ndarray
    modality: str


def real_head_takes() -> list[_Named]:
    """Colour renders of the real head in :data:`REAL_POSES`, and the frontal one shaded grey
    (a geometry-only scan); empty when the data is absent."""
    from tests.support.lps_landmarks import load_real_head, real_takes

    try:
        head = load_real_head()
    except (OSError, ValueError) as exc:
        print(f"real head skipped: {exc}")
        return []
    out = [
        _Named(t.name, t.color, t.xyz, t.truth, "real colour") for t in real_takes(head, REAL_POSES)
    ]
    front = out[0]
    out.append(_Named("front grey", shaded_image(front.xyz), front.xyz, front.truth, "real grey"))
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cache", type=Path, default=None, help="npz of the cohort's grids")
    parser.add_argument("--model", type=Path, default=None, help="a cascade to measure instead")
    args = parser.parse_args()
    if args.model is not None:  # every detection's default model (the package exports the
        # function ``detect`` under the module's name: the module itself from sys.modules)
        sys.modules["scan2morph.landmarks.detect"].MODEL_PATH = args.model
    cached_model()
    takes = [
        _Named(f"{t.subject}/{t.take}", t.color, t.xyz, t.truth, t.modality)
        for t in load_takes(args.cache)
    ]
    modalities = ("range", "stereo", "mesh", "rgbd")
    groups = [(m, lambda t, m=m: t.modality == m) for m in modalities]
    groups.append(("synthetic, all", lambda t: t.modality in modalities))
    groups += [(m, lambda t, m=m: t.modality == m) for m in ("real colour", "real grey")]
    evaluate(takes + real_head_takes(), groups)
    cohort = load_takes(args.cache)
    second_pass_report(cohort)
    jaw_truth_report(cohort)


def face_outline_distance(xyz: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (px) of each point to the nearest occluding contour of the range grid: a depth
    step of more than 4 mm between neighbouring pixels, or the edge of the data (the face's
    silhouette against the neck or the background, where iBUG puts the jawline)."""
    from scipy import ndimage

    z = np.nan_to_num(np.asarray(xyz, dtype=np.float64)[..., 2], nan=1e5)
    edge = np.zeros(z.shape, dtype=bool)
    for axis in (0, 1):
        step = np.abs(np.diff(z, axis=axis)) > 4.0
        near = np.minimum(z[:-1], z[1:]) if axis == 0 else np.minimum(z[:, :-1], z[:, 1:])
        nearer_first = (z[:-1] < z[1:]) if axis == 0 else (z[:, :-1] < z[:, 1:])
        # the contour pixel is the nearer one of the pair (the occluding side)
        a = step & nearer_first & (near < 1e5)
        b = step & ~nearer_first & (near < 1e5)
        if axis == 0:
            edge[:-1] |= a
            edge[1:] |= b
        else:
            edge[:, :-1] |= a
            edge[:, 1:] |= b
    dist = ndimage.distance_transform_edt(~edge)
    ij = np.clip(np.rint(points[:, ::-1]).astype(int), 0, np.array(dist.shape) - 1)
    return dist[ij[:, 0], ij[:, 1]]


def jaw_truth_report(takes: list[GridTake]) -> None:
    """How far the generator's jawline truth (points 4-14) lies from the face's outline, per
    label (range takes: the scanner's own frame, no virtual camera)."""
    print("\nGenerator jawline truth vs the face's silhouette (range takes, points 4-14, px):")
    by_label: dict[str, list[np.ndarray]] = {}
    for t in takes:
        if t.modality != "range":
            continue
        d = face_outline_distance(t.xyz, t.truth)
        by_label.setdefault(t.label, []).append(d[3:14])
    for label, ds in by_label.items():
        d = np.concatenate(ds)
        print(
            f"  {label:8s} median {np.median(d):5.2f}  p95 {np.percentile(d, 95):5.2f}  max {d.max():5.2f}"
        )


#: Second-pass steps: name -> the landmarks stage's parameters (None: the detector alone).
STEPS = {
    "detector": None,
    "+ carry stable": Params(track=False),
    "+ track moving": Params(),
}


def _agreement(take: GridTake, neutral: GridTake, points, neutral_points, transform) -> np.ndarray:
    """Distance (px on the neutral's grid) of a take's stable points, carried into the neutral
    by the rigid ``transform``, to the neutral's own."""
    idx = np.asarray(Params().stable_points) - 1
    lifted = sample_range(take.xyz, points[idx], take.take, 0.5)[0]
    found = range_pixels(neutral.xyz, transform_points(transform, lifted), neutral_points[idx])
    return np.linalg.norm(found - neutral_points[idx], axis=1)


def second_pass_report(takes: list[GridTake]) -> None:
    """The second pass step by step (see the module's docstring), per modality."""
    det = {(t.subject, t.take): detect(t.color, t.xyz, t.take) for t in takes}
    rows: dict[str, list] = {name: [] for name in STEPS}
    for t in takes:
        n = next(u for u in takes if u.subject == t.subject and u.take == "neutral")
        d, dn = det[(t.subject, t.take)], det[(n.subject, n.take)]
        transform = None
        if t is not n:
            transform = carry_stable(t.xyz, d.points, n.xyz, dn.points, Params().stable_points)
        for name, params in STEPS.items():
            pts, dt = d.points, 0.0
            if params is not None and t is not n:
                data = {
                    paths.range_image("neutral", "xyz"): n.xyz,
                    paths.range_image("neutral", "color"): n.color,
                    paths.landmarks("neutral"): dn.points,
                    paths.landmark_confidence("neutral"): dn.confidence,
                }
                take = Take(t.subject, t.take, "", t.label, "neutral", data)
                t0 = time.process_time()
                found = second_pass(
                    Landmarks(d.points, DETECTED, d.confidence),
                    take,
                    (t.xyz.astype(float), t.color),
                    params,
                )[0]
                dt, pts = time.process_time() - t0, found.points
            err = np.linalg.norm(pts - t.truth, axis=1)
            rel = agree = None
            if t is not n:
                rel = np.linalg.norm((pts - t.truth) - (dn.points - n.truth), axis=1)
                agree = _agreement(t, n, pts, dn.points, transform.transform)
            rows[name].append((t.modality, err, rel, agree, dt))
    print("\nSecond pass, step by step (px at 640 x 480; rel: a take's error minus its neutral's;")
    print("stable agreement: its stable points against the neutral's after alignment):")
    print(
        f"{'step / modality':<26} {'med':>6} {'p95':>6} {'rel-in':>7} {'rel-jaw':>7} {'agree':>6} {'cpu ms':>7}"
    )
    for name, results in rows.items():
        for mod in ("range", "stereo", "mesh", "rgbd", "all"):
            sel = [r for r in results if mod in ("all", r[0])]
            e = np.concatenate([r[1] for r in sel])
            rel = np.stack([r[2] for r in sel if r[2] is not None])
            agree = np.concatenate([r[3] for r in sel if r[3] is not None])
            cpu = [r[4] for r in sel if r[2] is not None]
            print(
                f"{name + ' ' + mod:<26} {np.median(e):6.2f} {np.percentile(e, 95):6.2f} "
                f"{np.median(rel[:, 17:]):7.2f} {np.median(rel[:, :17]):7.2f} "
                f"{np.nanmedian(agree):6.2f} {1000 * np.median(cpu):7.0f}"
            )


if __name__ == "__main__":
    main()
