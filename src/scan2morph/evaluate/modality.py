"""Accuracy by input modality: the truth seen through each take's pixel-grid camera, and the
per-modality summary of ``accuracy.json``.

A range or stereo take's pixel grid belongs to the camera whose frame is the take's frame, and
its truth already says so (``K``, ``D``). An RGB-D take's grid is the colour camera's while its
frame is the depth camera's, and a mesh take's grid is a virtual camera chosen at ingest; the
store records that camera (``/takes/{take}/camera/K``, ``distortion``, ``pose``), and
:func:`grid_view` re-expresses the truth in it so that the method's ideal motion (rays cast from
the grid's pixels) and the click scatter (true landmark projections) refer to the pixels the
pipeline used.
"""

from __future__ import annotations

from collections.abc import Mapping

import cv2
import numpy as np

from scan2morph.evaluate.truth import Truth
from scan2morph.store import paths

#: Per-take accuracy values summarised per modality: (stage, key, reducer).
_SUMMARY = (
    ("mesh", "rms_mm", "max"),
    ("mesh", "valid_share", "min"),
    ("align", "rotation_deg", "max"),
    ("align", "translation_mm", "max"),
    ("motion", "relative_error", "max"),
    ("motion", "normal_relative_error", "max"),
    ("motion", "material_relative_error", "max"),
)


def take_modality(store: Mapping[str, np.ndarray], take: str) -> str:
    """The take's modality as the store records it (``range`` for stores that predate it)."""
    value = store.get(paths.camera(take, "modality"), "range")
    value = value.decode() if isinstance(value, bytes) else value
    return str(np.asarray(value).item()) if isinstance(value, np.ndarray) else str(value)


def grid_view(truth: Truth, store: Mapping[str, np.ndarray], take: str) -> tuple[Truth, np.ndarray]:
    """The truth in the frame of the camera of the take's pixel grid.

    Parameters
    ----------
    truth : Truth
        The take's truth (``pose``: head -> the take's frame).
    store : mapping store path -> array
    take : str

    Returns
    -------
    view : Truth
        ``truth`` itself when the store records no camera pose for the take; otherwise with
        ``pose`` head -> grid camera, ``K`` and ``D`` that camera's, ``landmarks3d`` in its frame
        and ``landmarks2d`` their projections, px.
    rotation : (3, 3) float64
        Take frame -> grid camera rotation (a vector ``m`` of the take's frame is ``rotation @ m``
        in the view's frame).
    """
    if paths.camera(take, "pose") not in store:
        return truth, np.eye(3)
    cam_from_take = np.asarray(store[paths.camera(take, "pose")], dtype=np.float64)
    K = np.asarray(store[paths.camera(take, "K")], dtype=np.float64)
    D = np.asarray(store.get(paths.camera(take, "distortion"), np.zeros(5)), dtype=np.float64)
    R, t = cam_from_take[:3, :3], cam_from_take[:3, 3]
    lm3 = truth.landmarks3d @ R.T + t
    lm2 = cv2.projectPoints(lm3, np.zeros(3), np.zeros(3), K, D)[0].reshape(-1, 2)
    extra = {k: v for k, v in truth.extra.items() if k not in ("xyz_true", "segment")} | {"D": D}
    view = Truth(
        vertices=truth.vertices,
        faces=truth.faces,
        skin_faces=truth.skin_faces,
        pose=cam_from_take @ truth.pose,
        K=K,
        landmarks3d=lm3,
        landmarks2d=lm2,
        displacement=truth.displacement,
        extra=extra,
    )
    return view, R


def modality_summary(takes: Mapping[str, dict]) -> dict:
    """Worst (or least) value of each accuracy per modality, over that modality's takes.

    Parameters
    ----------
    takes : mapping take -> dict
        ``accuracy.json``'s per-take entries, each with ``modality``.

    Returns
    -------
    dict
        ``{modality: {"takes": [...], "mesh_rms_mm_max": ..., ...}}``; a value is None when no
        take of the modality has it. A depth-camera or stereo entry (``takes[t][modality]``
        with ``depth_rms_mm``) adds ``depth_rms_mm_max`` and ``coverage_min``.
    """
    out: dict[str, dict] = {}
    for modality in dict.fromkeys(t["modality"] for t in takes.values()):
        mine = [t for t in takes.values() if t["modality"] == modality]
        entry: dict = {"takes": [k for k, t in takes.items() if t["modality"] == modality]}
        for stage, key, how in _SUMMARY:
            entry[f"{stage}_{key}_{how}"] = _reduce(mine, stage, key, how)
        if modality in ("stereo", "rgbd"):  # their depth accuracy against the true surface
            entry["depth_rms_mm_max"] = _reduce(mine, modality, "depth_rms_mm", "max")
            entry["coverage_min"] = _reduce(mine, modality, "coverage", "min")
        out[modality] = entry
    return out


def _reduce(entries: list[dict], stage: str, key: str, how: str) -> float | None:
    values = [t[stage].get(key) for t in entries if isinstance(t.get(stage), dict)]
    values = [v for v in values if v is not None]
    if not values:
        return None
    return float(np.max(values) if how == "max" else np.min(values))


__all__ = ["grid_view", "modality_summary", "take_modality"]
