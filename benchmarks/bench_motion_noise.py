"""How landmark click noise sets the floor of the viseme motion error (issue #4's accuracy goal).

Run after ``make run``: ``.venv/bin/python benchmarks/bench_motion_noise.py [subject ...]``.
For each synthetic subject of the default cohort it scales the click noise of every take's
landmarks (stored landmarks minus the exact projected ones) to a range of standard deviations,
re-runs fitting, alignment and motion from the subject's store with the run's config
(``scan2morph.sweep.rerun_accuracy``, as a parameter sweep does) and prints, per viseme, the
motion error relative to the ideal motion (``relative_error``) and its part along the surface
normal (``normal_relative_error``).

Then it checks the pipeline's click-noise error bar (``scan2morph.motion.uncertainty``, which
sees no truth): for ``REALISATIONS`` fresh draws of the nominal click noise around the exact
landmarks it prints the error bar each draw's pipeline reports (``click_noise_relative``, mean
over draws) against the click-noise part of the error the truth shows, ``sqrt(mean(rel^2) -
rel0^2)`` with ``rel0`` the error at exact landmarks. Nothing is asserted; the printed tables are
the measurement.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import yaml

from scan2morph.evaluate.truth import read_truth
from scan2morph.stages import Run, Subject
from scan2morph.store import paths, read_part
from scan2morph.sweep import rerun_accuracy, sweep_settings
from scan2morph.template import load_template

ROOT = Path(__file__).resolve().parents[1]
#: Click noise standard deviations (px per coordinate) to measure.
NOISE_PX = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.75, 1.0)
#: Fresh click-noise draws for the error-bar check, and their seed.
REALISATIONS = 8
SEED = 7


def main(subjects: list[str]) -> int:
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    nominal = float(config["synthetic"]["scanner"]["click_noise_px"])
    takes = {t["take"]: t["kind"] for t in config["synthetic"]["takes"]}
    labels = {t["take"]: t["label"] for t in config["synthetic"]["takes"]}
    template = load_template(ROOT / "resources" / "template.npz")
    settings = sweep_settings(config, {})
    # the error bar at the nominal noise (not measured per draw): the check is of its propagation
    settings["motion_noise"]["click_noise_px"] = nominal
    for subject in subjects:
        store_path = ROOT / "results" / subject / f"{subject}.h5"
        if not store_path.exists():
            print(f"{store_path}: missing; run `make run` first")
            return 0
        store = read_part(store_path)
        run = Run(Subject(subject, takes, labels), template, settings)
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
                data[paths.landmarks(t)] = exact + (sigma / nominal) * (
                    np.asarray(store[paths.landmarks(t)]) - exact
                )
            t0 = time.perf_counter()
            acc = rerun_accuracy(data, run, truths, "fit")
            cells = [
                f"{acc['takes'][v]['motion']['relative_error']:6.3f} "
                f"({acc['takes'][v]['motion']['normal_relative_error']:.3f})"
                for v in visemes
            ]
            print(f"{sigma:9.2f} " + " ".join(f"{c:>13}" for c in cells), end="")
            print(f"   {time.perf_counter() - t0:.1f}")
            if sigma == 0.0:
                floor = {v: acc["takes"][v]["motion"]["relative_error"] for v in visemes}
        check_error_bar(subject, store, run, takes, truths, nominal, floor)
    return 0


def check_error_bar(subject, store, run, takes, truths, sigma, floor):
    """Print the reported click-noise error bar against the click-noise error the truth shows."""
    rng = np.random.default_rng(SEED)
    visemes = list(floor)
    measured = {v: [] for v in visemes}
    precision = []
    predicted = {v: [] for v in visemes}
    t0 = time.perf_counter()
    for _ in range(REALISATIONS):
        data = dict(store)
        for t in takes:
            exact = truths[t].landmarks2d
            data[paths.landmarks(t)] = exact + sigma * rng.standard_normal(exact.shape)
        acc = rerun_accuracy(data, run, truths, "fit")
        precision.append(acc["summary"]["click_noise_px_measured"])
        for v in visemes:
            measured[v].append(acc["takes"][v]["motion"]["relative_error"])
            predicted[v].append(acc["takes"][v]["motion"]["click_noise_relative"])
    print(
        f"\n{subject}: click-noise error at {sigma} px, {REALISATIONS} draws "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    print(
        f"click precision measured on the stable points: {np.mean(precision):.3f} px "
        f"(range {np.min(precision):.3f}-{np.max(precision):.3f})"
    )
    print(f"{'viseme':>8} {'error bar':>10} {'truth':>8} {'ratio':>6}")
    for v in visemes:
        truth = np.sqrt(max(np.mean(np.square(measured[v])) - floor[v] ** 2, 0.0))
        bar = float(np.mean(predicted[v]))
        print(f"{v:>8} {bar:10.3f} {truth:8.3f} {truth / bar:6.2f}")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:] or ["synth01", "synth02"]))
