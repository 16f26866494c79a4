"""Time template fitting per take: TPS warp + subdivision + bilinear sampling (640x480 scan).

Run: .venv/bin/python benchmarks/bench_fit.py
"""

from __future__ import annotations

import time

from scan2morph.synth import make_take
from scan2morph.template import (
    TPS,
    FitRules,
    build_template,
    fit_take,
    sample_range,
    subdivide_template,
)


def best_of(fn, repeats=5):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times)


def main():
    scan = make_take("bench", "car", "viseme", "car", seed=0)
    xyz, lm = scan["xyz"], scan["landmarks"]
    template = build_template()
    numbers, idx = template.fiducial_set("open")
    print(
        f"{'level':>5} {'V':>6} {'F':>6} {'subdivide ms':>13} {'warp ms':>8} {'sample ms':>10} {'fit_take ms':>12}"
    )
    for level in (0, 1, 2):
        fine = subdivide_template(template, level)
        spline = TPS.fit(template.vertices[idx], lm[numbers - 1])
        pts = spline(fine.vertices)
        t_sub = best_of(lambda level=level: subdivide_template(template, level))
        t_warp = best_of(
            lambda fine=fine: TPS.fit(template.vertices[idx], lm[numbers - 1])(fine.vertices)
        )
        t_sample = best_of(lambda pts=pts: sample_range(xyz, pts))
        t_fit = best_of(
            lambda level=level: fit_take(
                template, lm, xyz, (640, 480), "open", FitRules(level), "bench"
            )
        )
        print(
            f"{level:>5} {fine.n_vertices:>6} {len(fine.faces):>6} {t_sub:>13.2f} {t_warp:>8.2f} {t_sample:>10.2f} {t_fit:>12.2f}"
        )


if __name__ == "__main__":
    main()
