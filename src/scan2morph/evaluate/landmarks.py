"""Landmarks against the truth: how far each take's 68 points lie from the exact ones, px."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scan2morph.evaluate.modality import grid_view
from scan2morph.evaluate.truth import Truth
from scan2morph.io.landmarks import JAWLINE
from scan2morph.store import paths
from scan2morph.store.warnings import landmark_source

#: 0-based rows of the jawline (iBUG 1-17) and of the 51 inner-face points.
_JAW = np.asarray(JAWLINE) - 1
_INNER = np.setdiff1d(np.arange(68), _JAW)


def landmark_errors(points: np.ndarray, truth: np.ndarray) -> dict:
    """Distances of landmarks to the truth, px.

    Parameters
    ----------
    points, truth : (68, 2) float
        0-based pixels on the same grid.

    Returns
    -------
    dict
        ``median_px``, ``p95_px`` and ``max_px`` over the 68 points, ``inner_median_px`` and
        ``inner_p95_px`` over the 51 inner-face points, ``jaw_median_px`` over the jawline.
    """
    err = np.linalg.norm(np.asarray(points, float) - np.asarray(truth, float), axis=1)
    return {
        "median_px": float(np.median(err)),
        "p95_px": float(np.percentile(err, 95)),
        "max_px": float(err.max()),
        "inner_median_px": float(np.median(err[_INNER])),
        "inner_p95_px": float(np.percentile(err[_INNER], 95)),
        "jaw_median_px": float(np.median(err[_JAW])),
    }


def take_landmarks(store: Mapping[str, np.ndarray], truths: Mapping[str, Truth]) -> dict[str, dict]:
    """Each take's landmark errors against its truth seen through its grid's camera.

    Parameters
    ----------
    store : mapping store path -> array
    truths : mapping take -> Truth

    Returns
    -------
    dict take -> dict
        :func:`landmark_errors` with the take's ``source`` (``/takes/{take}/landmark_source``;
        ``clicked`` in a store from before it); takes without landmarks in the store are left
        out.
    """
    out = {}
    for take, truth in truths.items():
        if paths.landmarks(take) not in store:
            continue
        view = grid_view(truth, store, take)[0]
        errors = landmark_errors(store[paths.landmarks(take)], view.landmarks2d)
        out[take] = {"source": landmark_source(store, take)} | errors
    return out


def landmark_summary(per_take: Mapping[str, dict]) -> dict:
    """The cohort-style summary of :func:`take_landmarks`: over every point of every take,
    per source (``landmarks_{source}_median_px``, ``..._p95_px``)."""
    out = {}
    for source in sorted({e["source"] for e in per_take.values()}):
        medians = [e["median_px"] for e in per_take.values() if e["source"] == source]
        p95 = [e["p95_px"] for e in per_take.values() if e["source"] == source]
        key = source.replace("+", "_").replace(" ", "_")
        out[f"landmarks_{key}_median_px_max"] = float(np.max(medians))
        out[f"landmarks_{key}_p95_px_max"] = float(np.max(p95))
    return out


__all__ = ["landmark_errors", "landmark_summary", "take_landmarks"]
