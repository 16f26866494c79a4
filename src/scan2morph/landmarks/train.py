"""Train the landmark cascade from the project's own synthetic heads.

Usage::

    python -m scan2morph.landmarks.train --seed 1 --out src/scan2morph/landmarks/model.npz

The same seed and settings give identical weights. ``make detector`` runs it with the
committed model's settings. ``--cache DIR`` keeps the simulated takes so that retraining with
other cascade settings skips the simulation.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.landmarks.canonical import NOSE_CELL, SIZE, canonical
from scan2morph.landmarks.cascade import MIRROR, Cascade, features, fit_stage, save
from scan2morph.landmarks.data import Sample, make_samples
from scan2morph.landmarks.face import find_face

#: Model version: bump when the features, the frame or the training change.
VERSION = "1.0"
#: Training settings of the committed model.
DEFAULTS = {
    "subjects": 30,
    "takes": 10,
    "radii_mm": [9.0, 6.0, 4.0, 2.5, 1.5],
    "starts": 4,
    "ridge": 0.05,
    "jitter_mm": 4.0,
    "jitter_scale": 0.05,
    "jitter_deg": 4.0,
}
log = logging.getLogger("scan2morph")


def _prepared(samples: list[Sample]) -> tuple[list[np.ndarray], np.ndarray]:
    """Canonical channels and truth (cells) of every sample, and of its mirror image."""
    chans, truths = [], []
    for s in samples:
        try:
            can = canonical(find_face(s.xyz, s.name), s.color)
        except InputError as exc:
            log.warning("training take left out: %s", exc)
            continue
        cells = can.to_cells(s.truth)
        chans.append(can.channels)
        truths.append(cells)
        mirrored = can.channels[:, ::-1].copy()
        mirrored[..., 1] *= -1.0  # nx changes sign
        chans.append(mirrored)
        flipped = cells[MIRROR].copy()
        flipped[:, 0] = (SIZE - 1) - flipped[:, 0]
        truths.append(flipped)
    return chans, np.asarray(truths)


def _starts(init: np.ndarray, n: int, config: dict, rng: np.random.Generator) -> np.ndarray:
    """(n, 68, 2) jittered initial shapes: shift, scale and turn about the nose tip."""
    step = 0.6
    out = np.empty((n, *init.shape))
    for k in range(n):
        ang = np.deg2rad(rng.normal(0.0, config["jitter_deg"]))
        s = 1.0 + rng.normal(0.0, config["jitter_scale"])
        R = s * np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        shift = rng.normal(0.0, config["jitter_mm"] / step, 2)
        out[k] = NOSE_CELL + (init - NOSE_CELL) @ R.T + shift
    return out


def fit_cascade(chans: list[np.ndarray], truths: np.ndarray, seed: int, config: dict) -> Cascade:
    """Fit every stage of the cascade.

    Parameters
    ----------
    chans : list of (S, S, C) float32
        Canonical channels of the training takes.
    truths : (N, 68, 2) float
        Their truth, canonical cells.
    seed : int
        Seeds the initial jitter.
    config : dict
        :data:`DEFAULTS`' keys.

    Returns
    -------
    Cascade
    """
    rng = np.random.default_rng([int(seed), 0xCA5C])
    init = truths.mean(axis=0)
    m = int(config["starts"])
    shapes = np.stack([_starts(init, m, config, rng) for _ in chans])  # (N, m, 68, 2)
    target = np.repeat(truths[:, None], m, axis=1)
    stages = []
    for radius_mm in config["radii_mm"]:
        radius = radius_mm / 0.6
        feats = np.stack([features(c, s, radius) for c, s in zip(chans, shapes, strict=True)])
        X = feats.reshape(len(chans) * m, -1)
        Y = (target - shapes).reshape(len(chans) * m, -1)
        stage = fit_stage(X, Y, radius, float(config["ridge"]))
        shapes = shapes + ((X - stage.mean) / stage.scale @ stage.weights + stage.bias).reshape(
            shapes.shape
        )
        err = np.linalg.norm(target - shapes, axis=-1) * 0.6
        log.info("stage r=%.1f mm: training error median %.2f mm", radius_mm, np.median(err))
        stages.append(stage)
    meta = {"version": VERSION, "seed": int(seed), "config": config, "takes": len(chans) // 2}
    return Cascade(init, tuple(stages), meta)


def _cached_samples(seed: int, config: dict, cache: Path | None) -> list[Sample]:
    """The training takes, from ``cache`` when it holds them (same seed and counts)."""
    if cache is None:
        return make_samples(seed, config["subjects"], config["takes"])
    path = cache / f"samples-{seed}-{config['subjects']}x{config['takes']}.npz"
    if path.is_file():
        with np.load(path, allow_pickle=False) as z:
            names = [str(n) for n in z["names"]]
            return [Sample(z[f"c{i}"], z[f"x{i}"], z[f"t{i}"], n) for i, n in enumerate(names)]
    samples = make_samples(seed, config["subjects"], config["takes"])
    arrays = {"names": np.array([s.name for s in samples])}
    for i, s in enumerate(samples):
        arrays |= {f"c{i}": s.color, f"x{i}": s.xyz, f"t{i}": s.truth}
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays)
    return samples


def train(seed: int, config: dict | None = None, cache: Path | None = None) -> Cascade:
    """Simulate the training takes and fit the cascade.

    Parameters
    ----------
    seed : int
    config : dict, optional
        Overrides of :data:`DEFAULTS`.
    cache : Path, optional
        Directory keeping the simulated takes.

    Returns
    -------
    Cascade
    """
    config = DEFAULTS | dict(config or {})
    t0 = time.perf_counter()
    samples = _cached_samples(seed, config, cache)
    log.info("%d training takes simulated in %.0f s", len(samples), time.perf_counter() - t0)
    chans, truths = _prepared(samples)
    return fit_cascade(chans, truths, seed, config)


def main(argv: list[str] | None = None) -> int:
    """Command line: ``--seed N --out PATH [--subjects N] [--takes N] [--cache DIR]``."""
    parser = argparse.ArgumentParser(prog="python -m scan2morph.landmarks.train")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--subjects", type=int, default=DEFAULTS["subjects"])
    parser.add_argument("--takes", type=int, default=DEFAULTS["takes"])
    parser.add_argument("--ridge", type=float, default=DEFAULTS["ridge"])
    parser.add_argument("--cache", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.seed == 2009:
        parser.error("seed 2009 is the default cohort's: train on other identities")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    t0 = time.perf_counter()
    config = {"subjects": args.subjects, "takes": args.takes, "ridge": args.ridge}
    model = train(args.seed, config, args.cache)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save(model, args.out)
    log.info("trained in %.0f s: %s", time.perf_counter() - t0, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
