"""Cascaded shape regression (supervised descent) in the canonical frame.

The first, global stage reads the smoothed canonical channels (:mod:`scan2morph.landmarks.
canonical`) on a fixed 17 x 19 grid over the face (9 mm apart) and predicts the whole shape by
ridge regression: where the eyes, mouth and chin are, whatever the face's proportions. Each
following, local stage samples the channels on a 3 x 3 pattern of half-width ``radius`` cells
around each of the 68 current points (a stage's ``side`` x ``side`` pattern: 3 in the committed
model), standardises the 2448 values and adds a ridge-regressed update of all 136 coordinates;
they look closer and closer.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.jobs import write_npz
from scan2morph.tol import N_IBUG

#: iBUG-68 index of each point's mirror image (0-based).
MIRROR = np.array(
    list(range(16, -1, -1))  # jaw
    + list(range(26, 21, -1))
    + list(range(21, 16, -1))  # brows
    + [27, 28, 29, 30]  # nose bridge
    + [35, 34, 33, 32, 31]  # nostrils
    + [45, 44, 43, 42, 47, 46, 39, 38, 37, 36, 41, 40]  # eyes
    + [54, 53, 52, 51, 50, 49, 48, 59, 58, 57, 56, 55]  # outer lips
    + [64, 63, 62, 61, 60, 67, 66, 65],  # inner lips
    dtype=np.int64,
)
#: The 3 x 3 sampling pattern around a point, in units of the stage's radius.
PATTERN = np.array([(x, y) for y in (-1.0, 0.0, 1.0) for x in (-1.0, 0.0, 1.0)])


def pattern(side: int) -> np.ndarray:
    """The ``side`` x ``side`` sampling pattern (side**2, 2) spanning -1..1 (units of the
    stage's radius), row by row; ``side`` 3 is :data:`PATTERN`."""
    if side < 2:
        raise InputError("landmark cascade", f"pattern side: expected 2 or more, got {side}")
    t = np.linspace(-1.0, 1.0, int(side))
    return np.array([(x, y) for y in t for x in t])


#: The global stage's grid about the nose tip, mm (x right, y down).
GLOBAL_GRID_MM = np.array(
    [(x, y) for y in np.arange(-75.0, 88.0, 9.0) for x in np.arange(-72.0, 73.0, 9.0)]
)
#: Smoothing of the channels the global stage reads, canonical cells.
GLOBAL_BLUR = 3.0


@dataclass(frozen=True)
class Stage:
    """One regression stage.

    Attributes
    ----------
    radius : float
        Half-width of the sampling pattern, canonical cells; 0 for the global stage (it
        predicts the shape itself instead of an update).
    weights : (F, 136) float32
        Ridge weights on standardised features.
    bias : (136,) float32
    mean, scale : (F,) float32
        Feature standardisation.
    side : int
        Points per side of the local sampling pattern (:func:`pattern`).
    """

    radius: float
    weights: np.ndarray
    bias: np.ndarray
    mean: np.ndarray
    scale: np.ndarray
    side: int = 3


@dataclass(frozen=True)
class Cascade:
    """A trained cascade: the initial shape, the stages and the training record.

    Attributes
    ----------
    init : (68, 2) float64
        Mean training shape, canonical cells.
    stages : tuple of Stage
    meta : dict
        ``version``, ``seed`` and the training configuration.
    """

    init: np.ndarray
    stages: tuple[Stage, ...]
    meta: dict


def _sample(channels: np.ndarray, where: np.ndarray) -> np.ndarray:
    """Bilinear samples (n, C) of the channels at canonical points (n, 2); outside: no data."""
    flat = where.reshape(1, -1, 2).astype(np.float32)
    border = [3.0] + [0.0] * (channels.shape[2] - 1)
    vals = cv2.remap(
        channels,
        flat[..., 0],
        flat[..., 1],
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=border,
    )
    return vals.reshape(len(where), -1)


def global_features(channels: np.ndarray) -> np.ndarray:
    """The global stage's features: smoothed channels on :data:`GLOBAL_GRID_MM`, (F,)."""
    from scan2morph.landmarks.canonical import NOSE_CELL, STEP_MM

    smooth = cv2.GaussianBlur(channels, (0, 0), GLOBAL_BLUR)
    return _sample(smooth, NOSE_CELL + GLOBAL_GRID_MM / STEP_MM).reshape(-1)


def features(channels: np.ndarray, points: np.ndarray, radius: float, side: int = 3) -> np.ndarray:
    """Channel values around each point.

    Parameters
    ----------
    channels : (S, S, C) float32
        Canonical channels.
    points : (..., 68, 2) float
        Current shapes, canonical cells.
    radius : float
        Pattern half-width, cells.
    side : int
        Points per side of the pattern (:func:`pattern`).

    Returns
    -------
    (..., 68 * side**2 * C) float32
    """
    pts = np.asarray(points, dtype=np.float64)
    where = pts[..., :, None, :] + radius * pattern(side)  # (..., 68, side**2, 2)
    return _sample(channels, where.reshape(-1, 2)).reshape(*pts.shape[:-2], -1)


def run(
    model: Cascade, channels: np.ndarray, start: np.ndarray, first: int = 0, upto: int | None = None
) -> np.ndarray:
    """Run the cascade's stages ``first`` to ``upto`` from ``start``.

    Parameters
    ----------
    model : Cascade
    channels : (S, S, C) float32
    start : (..., 68, 2) float
        Initial shapes, canonical cells (several at once: an ensemble); a global stage
        replaces them by its prediction.
    first, upto : int
        Stages run: ``model.stages[first:upto]`` (all by default).

    Returns
    -------
    (..., 68, 2) float64
        The final shapes, canonical cells.
    """
    shape = np.array(start, dtype=np.float64)
    for stage in model.stages[first:upto]:
        if stage.radius == 0:
            f = (global_features(channels) - stage.mean) / stage.scale
            shape = np.broadcast_to((f @ stage.weights + stage.bias).reshape(68, 2), shape.shape)
            shape = shape.astype(np.float64)
            continue
        f = (features(channels, shape, stage.radius, stage.side) - stage.mean) / stage.scale
        shape = shape + (f @ stage.weights + stage.bias).reshape(shape.shape)
    return shape


def fit_stage(
    feats: np.ndarray, target: np.ndarray, radius: float, ridge: float, side: int = 3
) -> Stage:
    """Ridge regression of the shape updates on standardised features.

    Parameters
    ----------
    feats : (N, F) float
        Features of N training shapes.
    target : (N, 136) float
        Truth minus current shape (the global stage: the truth), canonical cells.
    radius : float
    ridge : float
        Ridge penalty per sample (the penalty is ``ridge * N``).
    side : int
        The features' pattern side, kept in the stage.

    Returns
    -------
    Stage
    """
    return ridge_path(feats, target, radius, [ridge], side)[0]


def ridge_path(
    feats: np.ndarray, target: np.ndarray, radius: float, ridges: list[float], side: int = 3
) -> list[Stage]:
    """:func:`fit_stage` for several ridge penalties at the cost of one (an eigen-decomposition
    of the Gram matrix serves them all; of the samples' kernel matrix when there are fewer
    samples than features, the same solution).

    Returns
    -------
    list of Stage
        One per penalty, in order.
    """
    X = np.asarray(feats, dtype=np.float64)
    mean = X.mean(axis=0)
    scale = np.maximum(X.std(axis=0), 1e-3)
    Xs = (X - mean) / scale
    ybar = target.mean(axis=0)
    # fewer samples than features: the same solution from the N x N kernel matrix,
    # (Xs^T Xs + l I)^-1 Xs^T = Xs^T (Xs Xs^T + l I)^-1, far cheaper to decompose
    dual = len(X) < X.shape[1]
    evals, evecs = np.linalg.eigh(Xs @ Xs.T if dual else Xs.T @ Xs)
    proj = evecs.T @ (target - ybar if dual else Xs.T @ (target - ybar))
    f32 = np.float32
    out = []
    for ridge in ridges:
        W = evecs @ (proj / (np.maximum(evals, 0.0) + ridge * len(X))[:, None])
        if dual:
            W = Xs.T @ W
        out.append(
            Stage(
                float(radius),
                W.astype(f32),
                ybar.astype(f32),
                mean.astype(f32),
                scale.astype(f32),
                int(side),
            )
        )
    return out


def save(model: Cascade, path: str | Path) -> None:
    """Write a cascade as ``.npz`` (weights float16, the training record as JSON text; the
    patterns' sides only when one is not 3, so the committed model's file is as before)."""
    arrays = {"init": model.init, "radii": np.array([s.radius for s in model.stages])}
    if any(s.side != 3 for s in model.stages):
        arrays["sides"] = np.array([s.side for s in model.stages])
    for k, s in enumerate(model.stages):
        arrays |= {
            f"weights{k}": s.weights.astype(np.float16),
            f"bias{k}": s.bias,
            f"mean{k}": s.mean,
            f"scale{k}": s.scale,
        }
    arrays["meta"] = np.array(json.dumps(model.meta, sort_keys=True))
    write_npz(path, arrays)


def load(path: str | Path) -> Cascade:
    """Read a cascade written by :func:`save`.

    Raises
    ------
    InputError
        A missing file or one that is not a cascade.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "landmark model not found (train it: make detector)")
    try:
        with np.load(path, allow_pickle=False) as z:
            radii = z["radii"]
            sides = z["sides"] if "sides" in z.files else np.full(len(radii), 3)
            stages = tuple(
                Stage(
                    float(r),
                    z[f"weights{k}"].astype(np.float32),
                    z[f"bias{k}"],
                    z[f"mean{k}"],
                    z[f"scale{k}"],
                    int(sides[k]),
                )
                for k, r in enumerate(radii)
            )
            init, meta = z["init"].astype(np.float64), json.loads(str(z["meta"]))
    except (KeyError, ValueError, OSError) as exc:
        raise InputError(path, f"not a landmark cascade: {exc}") from None
    if init.shape != (N_IBUG, 2):
        raise InputError(path, f"init: expected shape (68, 2), got {init.shape}")
    return Cascade(init, stages, meta)
