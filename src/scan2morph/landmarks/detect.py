"""Zero-click iBUG-68 landmarks of a take: :func:`detect`.

The face is found from the range data (:mod:`scan2morph.landmarks.face`), resampled into the
canonical frame (:mod:`scan2morph.landmarks.canonical`) and the cascade
(:mod:`scan2morph.landmarks.cascade`) is run from an ensemble of shifted starts, on the frame
and on its mirror image (the cascade was trained on both; its answers on the two differ by its
own error, not by the face). The points are the ensemble's median; a point's confidence falls
with the ensemble's spread there (a point the image does not pin down ends where its start put
it, or where the mirror image puts it).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.landmarks.canonical import NOSE_CELL, SIZE, STEP_MM, Canonical, canonical
from scan2morph.landmarks.cascade import MIRROR, Cascade, load, run
from scan2morph.landmarks.face import find_face
from scan2morph.tol import N_IBUG

#: The committed model (package data).
MODEL_PATH = Path(__file__).with_name("model.npz")
#: Detector name written with every detection.
DETECTOR = "scan2morph-cascade"
#: Ensemble starts: shifts (mm) and scale factors about the nose tip.
STARTS = (
    (0.0, 0.0, 1.0),
    (3.0, 0.0, 1.0),
    (-3.0, 0.0, 1.0),
    (0.0, 3.0, 1.0),
    (0.0, -3.0, 1.0),
    (0.0, 0.0, 1.05),
    (0.0, 0.0, 0.95),
)
#: Ensemble spread (RMS, mm) at which a point's confidence is 0.5.
HALF_CONFIDENCE_MM = 0.35


@dataclass(frozen=True)
class Detection:
    """Landmarks detected on a take's pixel grid.

    Attributes
    ----------
    points : (68, 2) float64
        iBUG-68 points, px: x right, y down, (0, 0) the centre of the top-left pixel (as
        :func:`scan2morph.io.read_pts` returns clicked ones).
    confidence : (68,) float64
        In [0, 1]; low means a large expected error.
    detector : str
    version : str
    """

    points: np.ndarray
    confidence: np.ndarray
    detector: str
    version: str


@lru_cache(maxsize=4)
def cached_model(path: str | None = None) -> Cascade:
    """The cascade at ``path`` (default: the committed model), loaded once per process."""
    return load(Path(path) if path else MODEL_PATH)


def check_grid(color: np.ndarray, xyz: np.ndarray, source: str) -> tuple[np.ndarray, np.ndarray]:
    """Check a take's colour and range grids: (H, W, 3) uint8 (or (H, W)) and (H, W, 3) float.

    Raises
    ------
    InputError
        Wrong shapes, sizes that differ, a non-numeric range grid.
    """
    color, xyz = np.asarray(color), np.asarray(xyz)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or xyz.dtype.kind != "f":
        raise InputError(
            source, f"xyz: expected an (H, W, 3) float grid, got {xyz.dtype} {xyz.shape}"
        )
    if color.ndim not in (2, 3) or color.shape[:2] != xyz.shape[:2]:
        raise InputError(
            source,
            f"color: expected {xyz.shape[0]} x {xyz.shape[1]} pixels like xyz, got {color.shape}",
        )
    return color, xyz


def global_stages(model: Cascade) -> int:
    """Number of leading global stages of a cascade (0 or 1)."""
    return int(bool(model.stages) and model.stages[0].radius == 0)


def ensemble_starts(init: np.ndarray) -> np.ndarray:
    """(K, 68, 2) starts of the ensemble: a shape (the global stage's prediction) shifted and
    scaled about the nose."""
    out = []
    for dx, dy, s in STARTS:
        out.append(NOSE_CELL + s * (init - NOSE_CELL) + np.array([dx, dy]) / STEP_MM)
    return np.stack(out)


def confidence_of(shapes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Median shape (68, 2) cells and per-point confidence (68,) of an ensemble (K, 68, 2)."""
    centre = np.median(shapes, axis=0)
    spread_mm = STEP_MM * np.sqrt(np.mean(np.sum((shapes - centre) ** 2, axis=-1), axis=0))
    return centre, 1.0 / (1.0 + (spread_mm / HALF_CONFIDENCE_MM) ** 2)


def mirror_channels(channels: np.ndarray) -> np.ndarray:
    """The canonical channels (S, S, C) mirrored left-right (the normal's x component turns)."""
    out = channels[:, ::-1].copy()
    out[..., 1] *= -1.0
    return out


def mirror_shapes(shapes: np.ndarray) -> np.ndarray:
    """Shapes (..., 68, 2) in canonical cells reflected left-right and renumbered
    (:data:`~scan2morph.landmarks.cascade.MIRROR`): a face's points on
    :func:`mirror_channels`, or those found there back in the frame."""
    out = np.array(shapes[..., MIRROR, :], dtype=np.float64)
    out[..., 0] = (SIZE - 1) - out[..., 0]
    return out


def ensemble_shapes(model: Cascade, channels: np.ndarray) -> np.ndarray:
    """The ensemble's final shapes (K, 68, 2) on one set of channels."""
    n_global = global_stages(model)
    base = run(model, channels, model.init, upto=n_global)
    return run(model, channels, ensemble_starts(base), first=n_global)


def detect_canonical(
    color: np.ndarray, xyz: np.ndarray, source: str, model: Cascade | None = None
) -> tuple[Canonical, np.ndarray]:
    """The canonical frame of a take and the ensemble's final shapes in it.

    Returns
    -------
    can : Canonical
    shapes : (2 K, 68, 2) float64
        Canonical cells: the K starts of :data:`STARTS` on the frame, then on its mirror image.
    """
    color, xyz = check_grid(color, xyz, source)
    model = model or cached_model()
    can = canonical(find_face(xyz, source), color)
    direct = ensemble_shapes(model, can.channels)
    return can, np.concatenate(
        [direct, mirror_shapes(ensemble_shapes(model, mirror_channels(can.channels)))]
    )


def detect(
    color: np.ndarray, xyz: np.ndarray, source: str, model: Cascade | None = None
) -> Detection:
    """Detect the iBUG-68 landmarks of one take.

    Parameters
    ----------
    color : (H, W, 3) uint8 or (H, W) uint8
        The take's colour (or grey) image on its pixel grid.
    xyz : (H, W, 3) float
        The take's points, mm, NaN where there is no surface (any right-handed frame).
    source : str
        ``subject/take`` or a file, named in errors.
    model : Cascade, optional
        Default: the committed model (loaded once per process).

    Returns
    -------
    Detection

    Raises
    ------
    InputError
        Bad grids; no face found, more than one face, a face too small, a profile view.
    """
    model = model or cached_model()
    can, shapes = detect_canonical(color, xyz, source, model)
    centre, conf = confidence_of(shapes)
    points = can.to_image(centre)
    if points.shape != (N_IBUG, 2):
        raise InputError(source, f"model: expected 68 points, got {points.shape}")
    return Detection(points, conf, DETECTOR, str(model.meta.get("version", "?")))
