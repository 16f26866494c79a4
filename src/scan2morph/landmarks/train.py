"""Train the landmark cascade from the project's own synthetic heads.

Usage::

    python -m scan2morph.landmarks.train --seed 1 --out src/scan2morph/landmarks/model.npz

and with ``--extra-subjects N`` (docs/landmarks.md) N more training subjects with wider faces
(closed eyes, other proportions) on top of the committed ones.

The same seed and settings give identical weights. ``make detector`` runs it with the
committed model's settings. ``--cache DIR`` keeps the simulated takes so that retraining with
other cascade settings skips the simulation.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.landmarks.canonical import NOSE_CELL, SIZE, STEP_MM, canonical
from scan2morph.landmarks.cascade import (
    Cascade,
    features,
    fit_stage,
    global_features,
    ridge_path,
    save,
)
from scan2morph.landmarks.data import (
    WIDE_RANGE,
    FaceShares,
    Sample,
    make_mesh_samples,
    make_samples,
    make_stereo_samples,
)
from scan2morph.landmarks.detect import mirror_channels, mirror_shapes
from scan2morph.landmarks.face import find_face
from scan2morph.synth.convention import CONVENTIONS, check_convention
from scan2morph.tol import N_IBUG

#: Model version: bump when the features, the frame or the training change.
VERSION = "1.1"
#: Training settings of the committed model.
DEFAULTS = {
    "subjects": 40,
    "takes": 8,
    "mesh_subjects": 10,
    "mesh_takes": 4,
    "stereo_subjects": 15,
    "stereo_takes": 4,
    "global": True,
    "radii_mm": [10.0, 6.0, 4.0, 2.5, 1.5],
    "pattern_side": 3,
    "ridge_per_point": False,
    "starts": 6,
    "ridges": [0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0],
    "jitter_mm": 3.0,
    "jitter_scale": 0.05,
    "jitter_deg": 4.0,
    "stretched": 3,
    "scale": [0.7, 1.15],
    "stretch_x": [0.8, 1.15],
    "stretch_up": [0.55, 1.1],
    "stretch_down": [0.8, 1.15],
    "brow_takes": 2,
    "extra_subjects": 0,
    "extra_closed_eyes": 1.0,
    "extra_wide_share": 0.0,
    "extra_knobs": list(WIDE_RANGE),
    "convention": CONVENTIONS[0],  # the generator's own points
}
#: ``radii_mm``: the local stages' pattern half-widths, mm, in order; ``pattern_side``: points
#: per side of their sampling pattern (3: 3 x 3); ``ridge_per_point``: each point's own ridge
#: penalty in the local stages (of ``ridges``, by the held-out identities) instead of one per stage.
#: ``brow_takes``: brow takes (``landmarks.data.BROW_LABELS``: a raise, a frown) of each
#: committed range and RGB-D subject, from a random stream of their own (the other takes as they
#: were). ``extra_*``: extra range and RGB-D training subjects (``wide000``, ...; ``takes`` each) added
#: to the committed ones, their faces drawn by ``landmarks.data.wide_identity`` with closed
#: eyes in a share ``extra_closed_eyes`` of them and the knobs ``extra_knobs`` redrawn in a share
#: ``extra_wide_share``; none for the committed model. ``convention``: where the training truth
#: puts the points (:data:`scan2morph.synth.convention.CONVENTIONS`: the generator's own, or our
#: annotation's iBUG rules with the jawline on each take's silhouette).
#: Every this many-th training identity is held out to choose each stage's ridge penalty.
HOLDOUT_EVERY = 5
log = logging.getLogger("scan2morph")


def _stretched(
    chans: np.ndarray, cells: np.ndarray, config: dict, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """A copy of a take's channels and truth resized about the nose tip: a face of another
    size (``scale``: every axis, the depth too) and other proportions (``stretch_x`` across,
    ``stretch_up`` above and ``stretch_down`` below the nose tip), so that the cascade meets
    faces unlike the generator's."""
    size = rng.uniform(*config["scale"])
    sx = size * rng.uniform(*config["stretch_x"])
    up = size * rng.uniform(*config["stretch_up"])
    down = size * rng.uniform(*config["stretch_down"])
    grid = np.arange(SIZE, dtype=np.float64) - NOSE_CELL[1]
    src_y = NOSE_CELL[1] + np.where(grid < 0, grid / up, grid / down)
    src_x = NOSE_CELL[0] + (np.arange(SIZE) - NOSE_CELL[0]) / sx
    map_x, map_y = np.meshgrid(src_x.astype(np.float32), src_y.astype(np.float32))
    out = cv2.remap(chans, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    depth = out[..., 0]
    out[..., 0] = np.where(depth >= 2.99, depth, depth * size)  # relief scales with the face
    rel = cells - NOSE_CELL
    moved = np.column_stack(
        [rel[:, 0] * sx, np.where(rel[:, 1] < 0, rel[:, 1] * up, rel[:, 1] * down)]
    )
    return out, NOSE_CELL + moved


def _identity(name: str) -> int:
    """A training take's identity number (``train007/...`` -> 7, ``mesh003/...`` -> 1003,
    ``stereo002/...`` -> 2002, ``wide004/...`` -> 3004)."""
    subject = name.split("/")[0]
    if subject.startswith("wide"):
        return 3000 + int(subject.removeprefix("wide"))
    if subject.startswith("mesh"):
        return 1000 + int(subject.removeprefix("mesh"))
    if subject.startswith("stereo"):
        return 2000 + int(subject.removeprefix("stereo"))
    return int(subject.removeprefix("train"))


def _prepared(
    samples: list[Sample], config: dict, seed: int
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Canonical channels, truth (cells) and identity number of every sample, of its mirror
    image and of ``config["stretched"]`` stretched copies of each."""
    rng = np.random.default_rng([int(seed), 0x57E7])
    chans, truths, groups = [], [], []
    for s in samples:
        try:
            can = canonical(find_face(s.xyz, s.name), s.color)
        except InputError as exc:
            log.warning("training take left out: %s", exc)
            continue
        cells = can.to_cells(s.truth)
        chans.append(can.channels)
        truths.append(cells)
        chans.append(mirror_channels(can.channels))
        truths.append(mirror_shapes(cells))
        for ch, cells_k in [(c, t) for c, t in zip(chans[-2:], truths[-2:], strict=True)]:
            for _ in range(int(config["stretched"])):
                warped, moved = _stretched(ch, cells_k, config, rng)
                chans.append(warped)
                truths.append(moved)
        groups += [_identity(s.name)] * (2 + 2 * int(config["stretched"]))
    return chans, np.asarray(truths), np.asarray(groups)


def _starts(init: np.ndarray, n: int, config: dict, rng: np.random.Generator) -> np.ndarray:
    """(n, 68, 2) jittered initial shapes: shift, scale and turn about the nose tip."""
    out = np.empty((n, *init.shape))
    for k in range(n):
        ang = np.deg2rad(rng.normal(0.0, config["jitter_deg"]))
        s = 1.0 + rng.normal(0.0, config["jitter_scale"])
        R = s * np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
        shift = rng.normal(0.0, config["jitter_mm"] / STEP_MM, 2)
        out[k] = NOSE_CELL + (init - NOSE_CELL) @ R.T + shift
    return out


def _predict(stage, X: np.ndarray) -> np.ndarray:
    """A stage's updates (N, 136) for features X (N, F)."""
    return (X - stage.mean) / stage.scale @ stage.weights + stage.bias


def _chosen_ridge(X: np.ndarray, Y: np.ndarray, held: np.ndarray, radius: float, config) -> float:
    """The ridge penalty of ``config["ridges"]`` that best predicts the held-out rows."""
    ridges = [float(r) for r in config["ridges"]]
    if len(ridges) == 1 or held.all() or not held.any():
        return ridges[0]
    errs = []
    for stage in ridge_path(X[~held], Y[~held], radius, ridges):
        res = (Y[held] - _predict(stage, X[held])).reshape(-1, 2)
        errs.append(float(np.median(np.linalg.norm(res, axis=1))))
    return ridges[int(np.argmin(errs))]


def _fit_local(X: np.ndarray, Y: np.ndarray, held: np.ndarray, radius: float, config: dict):
    """A local stage and its ridge penalty: one for the whole stage (the held-out rows' median
    error over all points) or, with ``config["ridge_per_point"]``, one per point (each point's
    two coordinates with the penalty that best predicts its held-out updates; a list)."""
    side = int(config["pattern_side"])
    ridges = [float(r) for r in config["ridges"]]
    if not config["ridge_per_point"] or len(ridges) == 1 or held.all() or not held.any():
        ridge = _chosen_ridge(X, Y, held, radius, config)
        return fit_stage(X, Y, radius, ridge, side), ridge
    errs = []
    for stage in ridge_path(X[~held], Y[~held], radius, ridges):
        res = (Y[held] - _predict(stage, X[held])).reshape(-1, N_IBUG, 2)
        errs.append(np.median(np.linalg.norm(res, axis=2), axis=0))
    best = np.argmin(np.asarray(errs), axis=0)  # (68,) index into ridges
    path = ridge_path(X, Y, radius, ridges, side)
    cols = np.repeat(best, 2)  # x and y of each point
    weights = np.stack([path[k].weights[:, j] for j, k in enumerate(cols)], axis=1)
    stage = replace(path[0], weights=weights)
    return stage, [ridges[k] for k in best]


def _fit_global(chans, truths: np.ndarray, groups: np.ndarray, config: dict):
    """The global stage, its out-of-fold predictions (N, 68, 2) (each identity predicted by a
    stage fitted without it: as good as on new faces) and its ridge penalty."""
    X = np.stack([global_features(c) for c in chans])
    Y = truths.reshape(len(truths), -1)
    fold = np.asarray(groups) % HOLDOUT_EVERY
    ridge = _chosen_ridge(X, Y, fold == HOLDOUT_EVERY - 1, 0.0, config)
    pred = np.empty_like(Y)
    stage = fit_stage(X, Y, 0.0, ridge)
    for k in range(HOLDOUT_EVERY):
        out = fold == k
        if out.all() or not out.any():
            pred[out] = stage.bias
            continue
        pred[out] = _predict(fit_stage(X[~out], Y[~out], 0.0, ridge), X[out])
    err = np.linalg.norm((Y - pred).reshape(-1, 2), axis=1) * STEP_MM
    log.info("global stage (ridge %g): out-of-fold error median %.2f mm", ridge, np.median(err))
    return stage, pred.reshape(truths.shape), ridge


def fit_cascade(
    chans: list[np.ndarray], truths: np.ndarray, groups: np.ndarray, seed: int, config: dict
) -> Cascade:
    """Fit every stage of the cascade.

    Parameters
    ----------
    chans : list of (S, S, C) float32
        Canonical channels of the training takes.
    truths : (N, 68, 2) float
        Their truth, canonical cells.
    groups : (N,) int
        Identity of each take: every :data:`HOLDOUT_EVERY`-th identity is held out to choose
        each stage's ridge penalty, then the stage is refitted on all takes.
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
    stages, ridges, base = [], [], np.repeat(init[None], len(chans), axis=0)
    if config["global"]:
        stage, base, ridge = _fit_global(chans, truths, groups, config)
        stages.append(stage)
        ridges.append(ridge)
    shapes = np.stack([_starts(b, m, config, rng) for b in base])  # (N, m, 68, 2)
    target = np.repeat(truths[:, None], m, axis=1)
    held = np.repeat(np.asarray(groups) % HOLDOUT_EVERY == HOLDOUT_EVERY - 1, m)
    side = int(config["pattern_side"])
    for radius_mm in config["radii_mm"]:
        radius = radius_mm / STEP_MM
        feats = np.stack([features(c, s, radius, side) for c, s in zip(chans, shapes, strict=True)])
        X = feats.reshape(len(chans) * m, -1)
        Y = (target - shapes).reshape(len(chans) * m, -1)
        stage, ridge = _fit_local(X, Y, held, radius, config)
        ridges.append(ridge)
        shapes = shapes + _predict(stage, X).reshape(shapes.shape)
        err = np.linalg.norm(target - shapes, axis=-1) * STEP_MM
        log.info(
            "stage r=%.1f mm (ridge %s): training error median %.2f mm",
            radius_mm,
            f"{ridge:g}" if np.isscalar(ridge) else f"per point {np.median(ridge):g} median",
            np.median(err),
        )
        stages.append(stage)
    config = config | {"chosen_ridges": ridges}
    meta = {
        "version": VERSION,
        "seed": int(seed),
        "config": config,
        "takes": len(chans) // (2 + 2 * int(config["stretched"])),  # each: mirrored, stretched
        "images": len(chans),
    }
    return Cascade(init, tuple(stages), meta)


def _cached(path: Path | None, make) -> list[Sample]:
    """``make()``'s samples, kept in (and read back from) ``path`` when given."""
    if path is not None and path.is_file():
        with np.load(path, allow_pickle=False) as z:
            names = [str(n) for n in z["names"]]
            return [Sample(z[f"c{i}"], z[f"x{i}"], z[f"t{i}"], n) for i, n in enumerate(names)]
    samples = make()
    if path is not None:
        arrays = {"names": np.array([s.name for s in samples])}
        for i, s in enumerate(samples):
            arrays |= {f"c{i}": s.color, f"x{i}": s.xyz, f"t{i}": s.truth}
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, **arrays)
    return samples


def _cached_samples(seed: int, config: dict, cache: Path | None) -> list[Sample]:
    """The training takes (range, RGB-D, mesh and stereo scans), from ``cache`` when it holds
    them."""
    n, k = config["subjects"], config["takes"]
    nm, km = config["mesh_subjects"], config["mesh_takes"]
    convention = check_convention(config["convention"], "training config: convention")
    # the default convention's files keep their names (caches made before the option)
    tag = "" if convention == CONVENTIONS[0] else f"-{convention}"
    out = _cached(
        cache / f"samples-{seed}-{n}x{k}{tag}.npz" if cache else None,
        lambda: make_samples(seed, n, k, convention=convention),
    )
    if nm and km:
        out += _cached(
            cache / f"mesh-{seed}-{nm}x{km}{tag}.npz" if cache else None,
            lambda: make_mesh_samples(seed, nm, km, convention=convention),
        )
    ns, ks = config["stereo_subjects"], config["stereo_takes"]
    if ns and ks:
        out += _cached(
            cache / f"stereo-{seed}-{ns}x{ks}{tag}.npz" if cache else None,
            lambda: make_stereo_samples(seed, ns, ks, convention=convention),
        )
    kb = int(config["brow_takes"])
    if n and kb:
        out += _cached(
            cache / f"brows-{seed}-{n}x{kb}{tag}.npz" if cache else None,
            lambda: make_samples(seed, n, kb, convention=convention, brows=True),
        )
    ne = int(config["extra_subjects"])
    if ne and k:
        extra = extra_shares(config)
        shares = f"c{extra.closed_eyes:g}-w{extra.wide:g}-{'+'.join(extra.knobs)}"
        out += _cached(
            cache / f"extra-{seed}-{ne}x{k}-{shares}{tag}.npz" if cache else None,
            lambda: make_samples(seed, ne, k, extra, convention=convention),
        )
    return out


def extra_shares(config: dict) -> FaceShares:
    """How the extra training subjects' faces are drawn (``config``'s ``extra_*`` keys)."""
    knobs = tuple(config["extra_knobs"])
    unknown = sorted(set(knobs) - set(WIDE_RANGE))
    if unknown:
        raise InputError(
            "training config", f"extra_knobs: unknown {unknown}; known {list(WIDE_RANGE)}"
        )
    shares = (float(config["extra_closed_eyes"]), float(config["extra_wide_share"]))
    if not all(0.0 <= v <= 1.0 for v in shares):
        raise InputError("training config", f"extra shares: expected 0-1, got {shares}")
    return FaceShares(*shares, knobs)


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
    chans, truths, groups = _prepared(samples, config, seed)
    return fit_cascade(chans, truths, groups, seed, config)


def main(argv: list[str] | None = None) -> int:
    """Command line: ``--seed N --out PATH [--subjects N] [--takes N] [--cache DIR]
    [--radii-mm R,...] [--pattern-side N] [--ridge-per-point] [--convention C] [--brow-takes N]
    [--extra-subjects N [--extra-closed-eyes P] [--extra-wide-share P] [--extra-knobs K,...]]``."""
    parser = argparse.ArgumentParser(prog="python -m scan2morph.landmarks.train")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--subjects", type=int, default=DEFAULTS["subjects"])
    parser.add_argument("--takes", type=int, default=DEFAULTS["takes"])
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument(
        "--radii-mm",
        default=",".join(f"{r:g}" for r in DEFAULTS["radii_mm"]),
        help="comma-separated local stages' pattern half-widths, mm",
    )
    parser.add_argument(
        "--pattern-side",
        type=int,
        default=DEFAULTS["pattern_side"],
        help="points per side of the local stages' sampling pattern",
    )
    parser.add_argument(
        "--ridge-per-point",
        action="store_true",
        help="each point's own ridge penalty in the local stages",
    )
    parser.add_argument(
        "--brow-takes",
        type=int,
        default=DEFAULTS["brow_takes"],
        help="brow takes (a raise, a frown) of each range/RGB-D subject",
    )
    parser.add_argument(
        "--extra-subjects",
        type=int,
        default=0,
        help="extra range/RGB-D subjects with wider faces, added to the committed ones",
    )
    parser.add_argument(
        "--convention",
        choices=CONVENTIONS,
        default=DEFAULTS["convention"],
        help="where the training truth puts the points: the generator's own or iBUG's rules",
    )
    parser.add_argument("--extra-closed-eyes", type=float, default=DEFAULTS["extra_closed_eyes"])
    parser.add_argument("--extra-wide-share", type=float, default=DEFAULTS["extra_wide_share"])
    parser.add_argument(
        "--extra-knobs",
        default=",".join(DEFAULTS["extra_knobs"]),
        help=f"comma-separated knobs redrawn, of {','.join(WIDE_RANGE)}",
    )
    args = parser.parse_args(argv)
    if args.seed == 2009:
        parser.error("seed 2009 is the default cohort's: train on other identities")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    t0 = time.perf_counter()
    config = {
        "subjects": args.subjects,
        "takes": args.takes,
        "radii_mm": [float(r) for r in args.radii_mm.split(",") if r],
        "pattern_side": args.pattern_side,
        "ridge_per_point": args.ridge_per_point,
        "brow_takes": args.brow_takes,
        "extra_subjects": args.extra_subjects,
        "extra_closed_eyes": args.extra_closed_eyes,
        "extra_wide_share": args.extra_wide_share,
        "extra_knobs": [k for k in args.extra_knobs.split(",") if k],
        "convention": args.convention,
    }
    try:
        extra_shares(config)
    except InputError as exc:
        parser.error(str(exc))
    model = train(args.seed, config, args.cache)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save(model, args.out)
    log.info("trained in %.0f s: %s", time.perf_counter() - t0, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
