"""Time take-to-neutral alignment and motion smoothing at template sizes (1.7k and 7k vertices).

Run: ``.venv/bin/python benchmarks/bench_align.py``. Prints the median wall time in ms of
``align_take`` (both refinements) and ``laplacian_smooth`` (w = 0.1, 30 iterations, with a
suppressed mask and a few missing vertices), and the alignment error against the known motion.
"""

from __future__ import annotations

import time
from functools import partial

import numpy as np
from scipy.spatial.transform import Rotation

from scan2morph.align import align_take, invert, rotation_angle_deg, transform_points
from scan2morph.motion import laplacian_smooth


def _grid_faces(nx: int, ny: int) -> np.ndarray:
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _face(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """Face-like height field, 160 x 200 mm."""
    x, y = np.meshgrid(np.linspace(-80, 80, nx), np.linspace(-100, 100, ny))

    def g(cx, cy, sx, sy=None):
        sy = sx if sy is None else sy
        return np.exp(-((x - cx) ** 2 / (2 * sx * sx) + (y - cy) ** 2 / (2 * sy * sy)))

    z = (
        60 * g(0, 0, 70)
        + 25 * g(0, 5, 10, 18)
        - 10 * g(-32, 30, 12)
        - 10 * g(32, 30, 12)
        + 10 * g(0, -80, 20)
        + 7 * g(0, 48, 35, 6)
        + 9 * g(-45, -5, 12)
        + 9 * g(45, -5, 12)
    )
    return np.stack([x.ravel(), y.ravel(), z.ravel()], 1), _grid_faces(nx, ny)


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main(seed: int = 0, repeats: int = 7) -> None:
    rng = np.random.default_rng(seed)
    print(f"{'V':>6} {'method':>16} {'align ms':>9} {'rot err deg':>12} {'t err mm':>9}")
    for nx, ny in ((37, 46), (75, 94)):
        v, f = _face(nx, ny)
        r_mouth = np.hypot(v[:, 0], v[:, 1] + 45)
        bump = np.where(r_mouth < 30, np.cos(np.pi / 2 * r_mouth / 30) ** 2, 0.0)
        upper = np.flatnonzero((v[:, 1] > -15) & (r_mouth > 40))
        pairs = np.array(
            [
                np.argmin(np.linalg.norm(v[:, :2] - p, axis=1))
                for p in [(-50, 40), (50, 40), (0, 30), (-60, 0), (60, 0), (0, 80)]
            ]
        )
        truth = np.eye(4)
        truth[:3, :3] = Rotation.from_rotvec(np.radians(5) * np.array([0.6, 0.0, 0.8])).as_matrix()
        truth[:3, 3] = [6.0, -8.0, 0.0]
        viseme = v + 10.0 * bump[:, None] * np.array([0.0, -1.0, 0.3])
        take = transform_points(invert(truth), viseme) + rng.normal(scale=0.1, size=v.shape)
        take[pairs] += rng.normal(scale=1.0, size=(6, 3))
        valid = np.ones(len(v), dtype=bool)
        centre = v[upper].mean(axis=0)
        for method in ("icp", "correspondence"):
            args = (take, valid, v, valid, f, pairs, upper, {"method": method})
            run = partial(align_take, *args, source="bench/take")
            run()  # warm-up (open3d import)
            ms = _median_ms(run, repeats)
            err = run().transform @ invert(truth)
            rot = rotation_angle_deg(err)
            t_err = np.linalg.norm(transform_points(err, centre) - centre)
            print(f"{len(v):>6} {method:>16} {ms:>9.2f} {rot:>12.4f} {t_err:>9.4f}")

        d = rng.normal(size=(len(v), 3))
        fixed = v[:, 1] > 0
        missing = rng.random(len(v)) < 0.02
        ms = _median_ms(partial(laplacian_smooth, d, f, 0.1, 30, fixed, missing), repeats)
        print(f"{len(v):>6} {'laplacian_smooth':>16} {ms:>9.2f}   (w=0.1, 30 iterations)")


if __name__ == "__main__":
    main()
