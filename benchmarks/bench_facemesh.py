"""An off-the-shelf candidate beside the project's detector: MediaPipe Face Mesh (issue #33).

MediaPipe's face landmark network (``face_landmark.tflite`` of the ``mediapipe`` 0.10.21 wheel
on PyPI, Apache-2.0; 468 mesh points on a 192 x 192 crop) is run with LiteRT
(``ai-edge-litert``, Apache-2.0), which imports with the lock's numpy 2 where ``mediapipe``
0.10.21 itself does not. Neither is a dependency of the project: this benchmark is run on demand,
with both fetched by hand::

    pip download mediapipe==0.10.21 --no-deps -d /tmp/mp
    unzip -j /tmp/mp/mediapipe-0.10.21-*.whl \\
        mediapipe/modules/face_landmark/face_landmark.tflite -d /tmp/mp
    .venv/bin/python -m pip install --target /tmp/litert --no-deps ai-edge-litert==2.3.0 \\
        flatbuffers backports.strenum ml_dtypes
    PYTHONPATH=/tmp/litert PYOPENGL_PLATFORM=osmesa .venv/bin/python \\
        benchmarks/bench_facemesh.py --tflite /tmp/mp/face_landmark.tflite [--cache F] \\
        [--train-cache G]

The crop is found as the project's detector finds the face (no image face detector): a square
of 190 mm (at the nose tip's scale) centred 10 mm above the nose tip, then twice MediaPipe's own
tracking crop (the points' bounding box 1.5 times, turned so that the outer eye corners 33 and
263 are level). The 468 points become iBUG-68 by a map learnt from the project's own synthetic
training takes (:mod:`scan2morph.landmarks.data`, training seed 1: range and RGB-D takes, mesh
scans and stereo takes, none of the default cohort's identities): each iBUG point is a
combination of the ``--neighbours`` mesh points nearest it on the mean face, weights summing to
one (so the map commutes with moving, turning and scaling the face), fitted by ridge-regularised
least squares over the training takes (``--ridge`` times the eye distance squared).

It prints, as ``bench_landmarks.py`` does (px at 640 x 480; median / 95th percentile; CPU per
take), the candidate on the default cohort's takes per modality (held out) and on the real
head's renders, the median per region, the takes whose face MediaPipe does not find (presence
below 0.5), and a bound: the real head's points through a map fitted on the real head's other
poses (leave one pose out), i.e. what MediaPipe's own points would give if the map knew the
annotation's conventions. ``--train-convention ibug`` fits the map on the same takes with
their truth under the iBUG annotation's conventions (:mod:`scan2morph.synth.convention`).
Nothing is asserted; the printed tables are the measurement.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
from bench_landmarks import (  # noqa: E402
    HEADER,
    _Named,
    _region_row,
    _row,
    load_takes,
    real_head_takes,
)

from scan2morph.landmarks.face import find_face  # noqa: E402

#: The network's input side, px.
SIDE = 192
#: MediaPipe's outer eye corners (subject's right, left): the crop's level line.
EYES = (33, 263)
#: The first crop: side and centre's height above the nose tip, mm.
FIRST_CROP_MM, FIRST_UP_MM = 190.0, 10.0
#: Tracking crops after the first.
ROUNDS = 2
#: Presence (sigmoid of the network's face flag) below which the face is taken as not found.
MIN_PRESENCE = 0.5


class FaceMesh:
    """The network, loaded once."""

    def __init__(self, path: Path):
        from ai_edge_litert.interpreter import Interpreter

        self.net = Interpreter(model_path=str(path), num_threads=1)
        self.net.allocate_tensors()
        self.input = self.net.get_input_details()[0]["index"]
        self.outputs = {d["name"]: d["index"] for d in self.net.get_output_details()}

    def crop_points(self, color, centre, side, angle):
        """The 468 points (468, 2) px in the image of the square crop of ``side`` px at
        ``centre`` turned by ``angle`` radians, and the face's presence in [0, 1]."""
        k = side / SIDE
        c, s = np.cos(angle) * k, np.sin(angle) * k
        a = np.array([[c, -s, 0.0], [s, c, 0.0]])  # crop pixel -> image pixel (centres)
        a[:, 2] = centre - a[:, :2] @ np.full(2, (SIDE - 1) / 2)
        rgb = color if color.ndim == 3 else np.repeat(color[..., None], 3, axis=2)
        crop = cv2.warpAffine(
            rgb, cv2.invertAffineTransform(a), (SIDE, SIDE), flags=cv2.INTER_LINEAR
        )
        self.net.set_tensor(self.input, crop[None].astype(np.float32) / 255.0)
        self.net.invoke()
        mesh = self.net.get_tensor(self.outputs["conv2d_21"]).reshape(468, 3)
        flag = float(self.net.get_tensor(self.outputs["conv2d_31"]).ravel()[0])
        uv = mesh[:, :2] - 0.5  # the network's pixel corners are at integers
        return uv @ a[:, :2].T + a[:, 2], 1.0 / (1.0 + np.exp(-flag))

    def points(self, color, xyz, source):
        """MediaPipe's 468 points of a take (px) and the last crop's presence."""
        face = find_face(np.asarray(xyz, dtype=np.float64), source)
        centre = face.nose_px - np.array([0.0, FIRST_UP_MM * face.px_per_mm])
        side, angle = FIRST_CROP_MM * face.px_per_mm, 0.0
        for _ in range(ROUNDS + 1):
            pts, presence = self.crop_points(color, centre, side, angle)
            centre, side, angle = tracking_crop(pts)
        return pts, presence


def tracking_crop(pts):
    """MediaPipe's crop from its own points: level eyes, the bounding box 1.5 times, square."""
    d = pts[EYES[1]] - pts[EYES[0]]
    angle = float(np.arctan2(d[1], d[0]))
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    local = pts @ rot  # coordinates along the level axes
    lo, hi = local.min(axis=0), local.max(axis=0)
    return rot @ (0.5 * (lo + hi)), 1.5 * float((hi - lo).max()), angle


def _similar(src, dst):
    """The similarity transform (a function) taking ``src`` (n, 2) nearest to ``dst``."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    u, sv, vt = np.linalg.svd((src - ms).T @ (dst - md))
    flip = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ flip @ vt
    scale = (sv * np.diag(flip)).sum() / ((src - ms) ** 2).sum()
    return lambda p: (p - ms) @ rot * scale + md


def fit_map(meshes, truths, neighbours, ridge):
    """The map 468 -> 68 points: per iBUG point, (indices, weights summing to 1).

    Parameters
    ----------
    meshes : (n, 468, 2) float
    truths : (n, 68, 2) float
    neighbours : int
        Mesh points per iBUG point (the nearest on the mean face).
    ridge : float
        Regularisation, in units of the eye distance squared per take.
    """
    to_first = [_similar(m, meshes[0]) for m in meshes]
    mn = np.stack([f(m) for f, m in zip(to_first, meshes, strict=True)])
    tn = np.stack([f(t) for f, t in zip(to_first, truths, strict=True)])
    mean_mesh, mean_truth = mn.mean(axis=0), tn.mean(axis=0)
    eye = np.linalg.norm(mean_mesh[EYES[1]] - mean_mesh[EYES[0]])
    out = []
    for k in range(truths.shape[1]):
        idx = np.argsort(np.linalg.norm(mean_mesh - mean_truth[k], axis=1))[:neighbours]
        base = mn[:, idx[0]]
        a = (mn[:, idx[1:]] - base[:, None]).transpose(0, 2, 1).reshape(-1, neighbours - 1)
        y = (tn[:, k] - base).ravel()
        g = a.T @ a + ridge * eye**2 * len(mn) * np.eye(neighbours - 1)
        c = np.linalg.solve(g, a.T @ y)
        out.append((idx, np.concatenate([[1.0 - c.sum()], c])))
    return out


def apply_map(mapping, mesh):
    """iBUG-68 points (68, 2) of MediaPipe's ``mesh`` (468, 2)."""
    return np.stack([w @ mesh[idx] for idx, w in mapping])


def training_takes(cache: Path | None, convention: str = "synth"):
    """The map's training takes (seed 1; from ``cache`` when it exists), their truth under the
    landmark ``convention`` (:data:`scan2morph.synth.convention.CONVENTIONS`)."""
    from scan2morph.landmarks.data import make_mesh_samples, make_samples, make_stereo_samples

    if cache is not None and cache.is_file():
        with np.load(cache, allow_pickle=False) as z:
            return [
                _Named(str(n), z[f"c{i}"], z[f"x{i}"], z[f"t{i}"], str(n).split("/")[-1])
                for i, n in enumerate(z["names"])
            ]
    samples = (
        make_samples(1, 20, 4, convention=convention)
        + make_mesh_samples(1, 6, 3, convention)
        + make_stereo_samples(1, 6, 2, convention)
    )
    if cache is not None:
        arrays = {"names": np.array([s.name for s in samples])}
        for i, s in enumerate(samples):
            arrays |= {f"c{i}": s.color, f"x{i}": s.xyz, f"t{i}": s.truth}
        np.savez(cache, **arrays)
    return [_Named(s.name, s.color, s.xyz, s.truth, s.name.split("/")[-1]) for s in samples]


def run_all(net, takes):
    """(mesh (468, 2), presence, CPU s) of each take."""
    out = []
    for t in takes:
        t0 = time.process_time()
        mesh, presence = net.points(t.color, np.asarray(t.xyz, dtype=np.float64), t.name)
        out.append((mesh, presence, time.process_time() - t0))
    return out


def report(mapping, takes, results, groups) -> None:
    print(HEADER)
    regions = []
    for gname, pick in groups:
        sel = [(t, r) for t, r in zip(takes, results, strict=True) if pick(t)]
        if not sel:
            continue
        errs = [np.linalg.norm(apply_map(mapping, r[0]) - t.truth, axis=1) for t, r in sel]
        print(_row(f"facemesh {gname}", errs, [r[2] for _, r in sel]))
        regions.append(_region_row(f"facemesh {gname}", errs))
    print("median per region (px)")
    print("\n".join(regions))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tflite", type=Path, required=True, help="face_landmark.tflite")
    parser.add_argument("--cache", type=Path, default=None, help="npz of the cohort's grids")
    parser.add_argument("--train-cache", type=Path, default=None, help="npz of the map's takes")
    parser.add_argument(
        "--train-convention",
        default="synth",
        choices=("synth", "ibug"),
        help="landmark conventions of the map's training truth (a cache holds one)",
    )
    parser.add_argument("--neighbours", type=int, default=8)
    parser.add_argument("--ridge", type=float, default=1e-3)
    args = parser.parse_args()
    net = FaceMesh(args.tflite)
    train = training_takes(args.train_cache, args.train_convention)
    fitted = run_all(net, train)
    found = [r[1] >= MIN_PRESENCE for r in fitted]
    print(f"map: {sum(found)} of {len(train)} training takes; face not found in", end=" ")
    print([t.name for t, f in zip(train, found, strict=True) if not f])
    mapping = fit_map(
        np.stack([r[0] for r, f in zip(fitted, found, strict=True) if f]),
        np.stack([t.truth for t, f in zip(train, found, strict=True) if f]),
        args.neighbours,
        args.ridge,
    )
    takes = [
        _Named(f"{t.subject}/{t.take}", t.color, t.xyz, t.truth, t.modality)
        for t in load_takes(args.cache)
    ]
    real = real_head_takes()
    results = run_all(net, takes + real)
    lost = [t.name for t, r in zip(takes + real, results, strict=True) if r[1] < MIN_PRESENCE]
    print(f"face not found (presence < {MIN_PRESENCE}): {lost}")
    modalities = ("range", "stereo", "mesh", "rgbd")
    groups = [(m, lambda t, m=m: t.modality == m) for m in modalities]
    groups.append(("synthetic, all", lambda t: t.modality in modalities))
    groups += [(m, lambda t, m=m: t.modality == m) for m in ("real colour", "real grey")]
    report(mapping, takes + real, results, groups)
    colour = [(t, r) for t, r in zip(real, results[len(takes) :], strict=True)]
    colour = [(t, r) for t, r in colour if t.modality == "real colour"]
    if len(colour) > 2:
        errs = []
        for i, (t, r) in enumerate(colour):
            rest = [c for j, c in enumerate(colour) if j != i]
            own = fit_map(
                np.stack([c[1][0] for c in rest]),
                np.stack([c[0].truth for c in rest]),
                args.neighbours,
                args.ridge,
            )
            errs.append(np.linalg.norm(apply_map(own, r[0]) - t.truth, axis=1))
        print("bound: the real head through a map fitted on its other poses")
        print(_row("facemesh real, own map", errs, [r[2] for _, r in colour]))
        print(_region_row("facemesh real, own map", errs))


if __name__ == "__main__":
    main()
