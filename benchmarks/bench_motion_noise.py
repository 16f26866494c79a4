"""How landmark click noise sets the floor of the viseme motion error (issue #4's accuracy goal).

Run after ``make run``: ``.venv/bin/python benchmarks/bench_motion_noise.py [subject ...]``.
For each synthetic subject of the default cohort it scales the click noise of every take's
landmarks (stored landmarks minus the exact projected ones) to a range of standard deviations,
re-runs fitting, alignment and motion from the subject's store with the run's config
(``scan2morph.report.rerun_accuracy``, as a parameter sweep does) and prints, per viseme, the
motion error relative to the ideal motion (``relative_error``) and its part along the surface
normal (``normal_relative_error``). Nothing is asserted; the printed table is the measurement.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import yaml

from scan2morph.evaluate.truth import read_truth
from scan2morph.report import rerun_accuracy
from scan2morph.report.sweep import sweep_settings
from scan2morph.store import read_part
from scan2morph.template import load_template

ROOT = Path(__file__).resolve().parents[1]
#: Click noise standard deviations (px per coordinate) to measure.
NOISE_PX = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.75, 1.0)


def main(subjects: list[str]) -> int:
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    nominal = float(config["synthetic"]["scanner"]["click_noise_px"])
    takes = {t["take"]: t["kind"] for t in config["synthetic"]["takes"]}
    template = load_template(ROOT / "resources" / "template.npz")
    settings = sweep_settings(config, {})
    for subject in subjects:
        store_path = ROOT / "results" / subject / f"{subject}.h5"
        if not store_path.exists():
            print(f"{store_path}: missing; run `make run` first")
            return 0
        store = read_part(store_path)
        truths = {
            t: read_truth(ROOT / "results" / "synthetic" / subject / "truth" / f"{t}.npz")
            for t in takes
        }
        visemes = [t for t, k in takes.items() if k == "viseme"]
        print(f"\n{subject}: relative_error (normal part) per viseme; nominal noise {nominal} px")
        print(f"{'noise px':>9} " + " ".join(f"{v:>13}" for v in visemes) + "   seconds")
        for sigma in NOISE_PX:
            data = dict(store)
            for t in takes:
                exact = truths[t].landmarks2d
                data[f"/takes/{t}/landmarks"] = exact + (sigma / nominal) * (
                    np.asarray(store[f"/takes/{t}/landmarks"]) - exact
                )
            t0 = time.perf_counter()
            acc = rerun_accuracy(data, settings, template, takes, truths, "fit", subject)
            cells = [
                f"{acc['takes'][v]['motion']['relative_error']:6.3f} "
                f"({acc['takes'][v]['motion']['normal_relative_error']:.3f})"
                for v in visemes
            ]
            print(f"{sigma:9.2f} " + " ".join(f"{c:>13}" for c in cells), end="")
            print(f"   {time.perf_counter() - t0:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:] or ["synth01", "synth02"]))
