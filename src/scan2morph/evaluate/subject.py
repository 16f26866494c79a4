"""A synthetic subject's accuracy report (``accuracy.json``): every stage against ground truth."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from scan2morph.evaluate.mesh import alignment_accuracy, mesh_accuracy
from scan2morph.evaluate.modality import grid_view, modality_summary, take_modality
from scan2morph.evaluate.motion import (
    ideal_motion,
    material_accuracy,
    motion_accuracy,
    template_lip_sides,
    true_motions,
)
from scan2morph.evaluate.scan import face_region, stereo_accuracy
from scan2morph.evaluate.truth import Truth
from scan2morph.geometry import vertex_normals
from scan2morph.motion.smooth import Relief, laplacian_smooth
from scan2morph.motion.uncertainty import noise_by_take
from scan2morph.store import paths

#: Segment label of skin in a stereo truth's ``segment`` image (``scan2morph.synth.head.SEG_SKIN``;
#: not imported, so that evaluating does not load the renderer).
SEG_SKIN = 0


@dataclass(frozen=True)
class IdealMotion:
    """How :func:`subject_accuracy` makes the ideal motion, the reference of a viseme's motion
    error: the pipeline's own fit of the true surface, smoothed as the pipeline smooths.

    Attributes
    ----------
    template : Template, optional
        The base template; with ``fiducial_sets`` (take -> set) and ``levels`` it gives the ideal
        motion (see ``evaluate.motion``). Without it, motion is compared to material motion only.
    fiducial_sets : mapping take -> str, optional
    levels : int
        Template subdivisions.
    smoothing : mapping, optional
        ``w``, ``iterations`` and ``confidence_relief`` of the pipeline's smoothing, applied with
        its mask (and the take's ``refine/confidence``, when the store has it) to the ideal
        motion for the ``relative_error`` reference.
    max_slope_deg : float, optional
        The fit's depth-step rule (degrees), applied to the ideal motion too.
    """

    template: object = None
    fiducial_sets: Mapping[str, str] | None = None
    levels: int = 1
    smoothing: Mapping[str, float] | None = None
    max_slope_deg: float | None = None


def subject_accuracy(
    store: Mapping[str, np.ndarray],
    truths: Mapping[str, Truth],
    neutral: str,
    visemes: list[str],
    reference: IdealMotion | None = None,
    expressions: Sequence[str] = (),
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
    reference : IdealMotion, optional
        How the ideal motion, the reference of a viseme's motion error, is made (default: the
        material motion, unsmoothed).
    expressions : sequence of str
        Expression take ids whose displacement fields (``/expressions/{take}/displacement``)
        are measured against the material motion (``expression`` entry).

    Returns
    -------
    dict
        ``{"units": ..., "takes": {take: {"mesh": ..., "align": ..., "motion": ...}}, "summary": ...}``
    """
    im = IdealMotion() if reference is None else reference
    takes: dict[str, dict] = {}
    n_vertices = store[paths.mesh(neutral, "vertices")]
    n_normals = vertex_normals(n_vertices, store[paths.template("faces")])
    # the pipeline's own error bar (no truth), shown beside the error the truth shows
    bars = noise_by_take(store)
    # the lip each vertex is on: at rest the lips meet, and a vertex of one is not the other's skin
    sides = None
    if paths.template("vertices2d") in store:
        sides = template_lip_sides(store[paths.template("vertices2d")])
    measured = [t for t in truths if t in visemes or t in expressions]
    materials = true_motions(n_vertices, truths[neutral], {t: truths[t] for t in measured}, sides)
    # each truth seen through the camera of its take's pixel grid (RGB-D: colour camera; mesh:
    # the virtual camera), with the rotation from the take's frame into that camera
    views = {take: grid_view(truth, store, take) for take, truth in truths.items()}
    for take, truth in truths.items():
        entry = _take_entry(store, take, truth, truths[neutral] if take != neutral else None)
        if take in visemes:
            entry["motion"] = _viseme_motion(
                store, take, neutral, materials[take], views, im, n_normals
            )
            if take in bars:
                rel = bars[take]["relative"]
                entry["motion"]["click_noise_relative"] = rel if np.isfinite(rel) else None
        if take in expressions and paths.expression(take, "displacement") in store:
            field = np.asarray(store[paths.expression(take, "displacement")], dtype=np.float64)
            entry["expression"] = material_accuracy(
                field, materials[take], n_normals, np.ones(len(field), dtype=bool)
            )
        takes[take] = entry
    summary = _summary(takes)
    summary |= _click_noise(store, {t: views[t][0] for t in truths}, neutral, visemes)
    summary |= _stereo_summary(takes)
    summary["by_modality"] = modality_summary(takes)
    return {
        "units": {"distances": "mm", "angles": "degrees", "relative": "fraction"},
        "takes": takes,
        "summary": summary,
    }


def _take_entry(store, take: str, truth: Truth, neutral_truth: Truth | None) -> dict:
    """A take's fitted mesh against its truth; a stereo or RGB-D take's depth over the face; a
    take's alignment (``neutral_truth`` None for the neutral itself)."""
    v, valid = store[paths.mesh(take, "vertices")], store[paths.mesh(take, "valid")]
    modality = take_modality(store, take)
    entry = {"modality": modality, "mesh": mesh_accuracy(v, valid, truth)}
    if "xyz_true" in truth.extra and paths.range_image(take, "xyz") in store:
        # a stereo or RGB-D take: depth error and coverage over the face
        face = face_region(truth.extra["segment"] == SEG_SKIN, truth.landmarks2d)
        entry["rgbd" if modality == "rgbd" else "stereo"] = stereo_accuracy(
            np.asarray(store[paths.range_image(take, "xyz")], dtype=np.float64),
            truth.extra["xyz_true"],
            face,
            source=take,
        )
    if neutral_truth is not None:
        entry["align"] = alignment_accuracy(
            store[paths.align(take, "transform")], v, valid, truth, neutral_truth
        )
    return entry


def _viseme_motion(store, take: str, neutral: str, material, views, im, n_normals) -> dict:
    """A viseme's motion against its material motion and the method-ideal one (``im``: how the
    ideal is made; without a template the material motion is the reference too)."""
    ideal = material
    if im.template is not None:
        sets = (im.fiducial_sets[neutral], im.fiducial_sets[take])
        view_n, rot_n = views[neutral]
        ideal = ideal_motion(im.template, view_n, views[take][0], sets, im.levels, im.max_slope_deg)
        ideal = ideal @ rot_n  # the neutral camera's frame -> the neutral frame
    processed = None
    if im.smoothing is not None:
        # the same steps as the take's: shorter where its refinement measured the skin
        processed = laplacian_smooth(
            ideal,
            store[paths.template("faces")],
            w=im.smoothing["w"],
            iterations=im.smoothing["iterations"],
            fixed=store[paths.mask("suppressed")],
            missing=~np.isfinite(ideal).all(axis=1),
            relief=Relief(
                store.get(paths.refine(take, "confidence")), im.smoothing["confidence_relief"]
            ),
        )
    return motion_accuracy(
        store[paths.viseme(take, "motion")],
        store[paths.viseme(take, "motion_raw")],
        ideal,
        material,
        store[paths.mask("suppressed")],
        processed,
        normals=n_normals,
    )


def _summary(takes: Mapping[str, dict]) -> dict:
    """The worst value of each measure over the takes."""

    def worst(stage, key):
        values = [t[stage].get(key) for t in takes.values() if stage in t]
        values = [v for v in values if v is not None]
        return float(np.max(values)) if values else None

    return {
        "motion_material_relative_error_max": worst("motion", "material_relative_error"),
        "expression_material_relative_error_max": worst("expression", "material_relative_error"),
        "mesh_rms_mm_max": worst("mesh", "rms_mm"),
        "align_rotation_deg_max": worst("align", "rotation_deg"),
        "align_translation_mm_max": worst("align", "translation_mm"),
        "motion_relative_error_max": worst("motion", "relative_error"),
        "motion_normal_relative_error_max": worst("motion", "normal_relative_error"),
        "masked_true_motion_share_max": worst("motion", "masked_true_motion_share"),
        "motion_click_noise_relative_max": worst("motion", "click_noise_relative"),
    }


def _stereo_summary(takes: Mapping[str, dict]) -> dict:
    """The stereo takes' worst depth error and coverage (empty without stereo takes)."""
    summary = {}
    stereo = [
        t["stereo"]
        for t in takes.values()
        if "stereo" in t and t["stereo"]["depth_rms_mm"] is not None
    ]
    if stereo:  # only subjects with stereo takes get the stereo summary
        summary["stereo_depth_rms_mm_max"] = max(s["depth_rms_mm"] for s in stereo)
        summary["stereo_coverage_min"] = min(s["coverage"] for s in stereo)
    return summary


def _click_noise(store, truths, neutral, visemes) -> dict:
    """The click precision the pipeline measured and used, beside the true click scatter.

    True: RMS over the stable points, the neutral and the visemes, and both image coordinates of
    the clicked minus the exact landmarks (px); empty without ``/motion_noise/stable_points``.
    """
    if paths.motion_noise("stable_points") not in store:
        return {}
    idx = np.asarray(store[paths.motion_noise("stable_points")], dtype=np.int64) - 1
    diffs = [
        np.asarray(store[paths.landmarks(t)], dtype=np.float64)[idx] - truths[t].landmarks2d[idx]
        for t in [neutral, *visemes]
    ]
    measured = float(store[paths.motion_noise("click_noise_measured_px")])
    return {
        "click_noise_px_true": float(np.sqrt(np.mean(np.square(diffs)))),
        "click_noise_px_measured": measured if np.isfinite(measured) else None,
        "click_noise_px_used": float(store[paths.motion_noise("click_noise_px")]),
    }
