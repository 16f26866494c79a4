"""A synthetic subject's accuracy report (``accuracy.json``): every stage against ground truth."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scan2morph.evaluate.mesh import alignment_accuracy, mesh_accuracy
from scan2morph.evaluate.motion import motion_accuracy, true_motion
from scan2morph.evaluate.truth import Truth


def subject_accuracy(
    store: Mapping[str, np.ndarray],
    truths: Mapping[str, Truth],
    neutral: str,
    visemes: list[str],
) -> dict:
    """Errors of one subject's pipeline outputs against its ground truth.

    Parameters
    ----------
    store : mapping store path -> array
        The subject's datasets (``/takes/{take}/mesh/...``, ``/takes/{take}/align/...``,
        ``/mask/suppressed``, ``/visemes/{take}/...``).
    truths : mapping take -> Truth
    neutral : str
        The neutral take id.
    visemes : list of str
        Viseme take ids.

    Returns
    -------
    dict
        ``{"units": ..., "takes": {take: {"mesh": ..., "align": ..., "motion": ...}}, "summary": ...}``
    """
    takes: dict[str, dict] = {}
    n_vertices = store[f"/takes/{neutral}/mesh/vertices"]
    for take, truth in truths.items():
        v, valid = store[f"/takes/{take}/mesh/vertices"], store[f"/takes/{take}/mesh/valid"]
        entry = {"mesh": mesh_accuracy(v, valid, truth)}
        if take != neutral:
            entry["align"] = alignment_accuracy(
                store[f"/takes/{take}/align/transform"], v, valid, truth, truths[neutral]
            )
        if take in visemes:
            m_true = true_motion(n_vertices, truths[neutral], truth)
            entry["motion"] = motion_accuracy(
                store[f"/visemes/{take}/motion"],
                store[f"/visemes/{take}/motion_raw"],
                m_true,
                store["/mask/suppressed"],
            )
        takes[take] = entry

    def worst(stage, key):
        values = [t[stage][key] for t in takes.values() if stage in t]
        return float(np.max(values)) if values else None

    return {
        "units": {"distances": "mm", "angles": "degrees", "relative": "fraction"},
        "takes": takes,
        "summary": {
            "mesh_rms_mm_max": worst("mesh", "rms_mm"),
            "align_rotation_deg_max": worst("align", "rotation_deg"),
            "align_translation_mm_max": worst("align", "translation_mm"),
            "motion_relative_error_max": worst("motion", "relative_error"),
            "masked_true_motion_share_max": worst("motion", "masked_true_motion_share"),
        },
    }
