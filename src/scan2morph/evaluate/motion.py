"""Accuracy of viseme motion vectors and of the stencil mask against ground truth.

Two references, because template-based correspondence is itself a model:

- **ideal motion** (what the method gives from perfect data): the template warped by the thin-plate
  spline to the *exact* landmarks of both takes, each warped vertex's pixel ray cast onto the
  *exact* surface, the take's point carried into the neutral frame by the *true* pose, minus the
  neutral's point. Errors against it are what noise, holes, repair, alignment, masking and
  smoothing cost; the issue's accuracy goal refers to it.
- **material motion** (physics): the motion of the material point a neutral vertex sits on (its
  closest point on the true neutral surface, carried to the same barycentric point of the take's
  true mesh; all takes share one topology). Errors against it add the correspondence model's own
  error (the spline places vertices between landmarks, skin slides differently).
"""

from __future__ import annotations

from collections.abc import Mapping

import cv2
import numpy as np
from scipy.spatial import cKDTree

from scan2morph.errors import InputError
from scan2morph.evaluate.truth import Truth, closest_points
from scan2morph.open3d_light import open3d, triangle_scene
from scan2morph.template.mesh import IBUG_CANONICAL, INNER_LIPS
from scan2morph.template.regions import inner_lip_midline, lip_side
from scan2morph.template.sample import behind_steps
from scan2morph.template.subdivide import subdivide_template
from scan2morph.template.tps import TPS


def ideal_points(
    template, truth: Truth, fiducial_set: str, levels: int, max_slope_deg: float | None = None
) -> np.ndarray:
    """(V, 3) template vertices sampled from the exact surface at the spline of exact landmarks.

    The scanner frame is the camera frame of ``truth.K`` (and the distortion ``D`` of a stereo
    take's left camera, when present); NaN where a vertex's ray misses the surface or hits a
    non-skin face (the mouth cavity, an eyeball), where the method has no data to sample, and,
    with ``max_slope_deg``, where the method's depth-step rule drops the vertex
    (:func:`scan2morph.template.sample.behind_steps`: a chin contour vertex on the neck).
    """
    numbers, idx = template.fiducial_set(fiducial_set)
    fine = subdivide_template(template, levels)
    pts = TPS.fit(template.vertices[idx], truth.landmarks2d[numbers - 1])(fine.vertices)
    # The vertex's ray and four rays half a pixel away: where their depths disagree the vertex
    # sits on a silhouette (lip contour, jaw line) and its ideal position is not defined.
    offsets = np.array([[0, 0], [0.5, 0], [-0.5, 0], [0, 0.5], [0, -0.5]])
    probe = (pts[None, :, :] + offsets[:, None, :]).reshape(-1, 2)
    dist = truth.extra.get("D")
    norm = cv2.undistortPoints(
        probe.reshape(-1, 1, 2).astype(np.float64),
        truth.K,
        None if dist is None else np.asarray(dist, float),
    ).reshape(-1, 2)
    rays = np.column_stack([np.zeros((len(probe), 3)), norm, np.ones(len(probe))]).astype(
        np.float32
    )
    rays[:, 3:] /= np.linalg.norm(rays[:, 3:], axis=1, keepdims=True)
    o3d = open3d()

    hit = triangle_scene(truth.posed_vertices(), truth.faces).cast_rays(o3d.core.Tensor(rays))
    t = hit["t_hit"].numpy().astype(np.float64).reshape(len(offsets), -1)
    face = hit["primitive_ids"].numpy().astype(np.int64).reshape(len(offsets), -1)
    out = rays[: len(pts), 3:].astype(np.float64) * t[0][:, None]
    seen = np.isfinite(t).all(axis=0)
    seen[seen] = truth.skin_faces[face[0, seen]] & (np.ptp(t[:, seen], axis=0) < SILHOUETTE_MM)
    out[~seen] = np.nan
    if max_slope_deg is not None:
        out[behind_steps(out, fine.faces, max_slope_deg)] = np.nan
    return out


#: Depth spread (mm) over half a pixel beyond which a vertex is on a silhouette.
SILHOUETTE_MM = 5.0


def ideal_motion(
    template,
    neutral: Truth,
    take: Truth,
    sets: tuple[str, str],
    levels: int,
    max_slope_deg: float | None = None,
) -> np.ndarray:
    """(V, 3) motion the method gives from perfect data, neutral frame, mm (NaN where undefined).

    ``sets`` are the fiducial sets of the neutral and of the take; ``max_slope_deg`` is the
    method's depth-step rule (see :func:`ideal_points`).
    """
    p_n = ideal_points(template, neutral, sets[0], levels, max_slope_deg)
    p_t = ideal_points(template, take, sets[1], levels, max_slope_deg)
    true = neutral.pose @ np.linalg.inv(take.pose)
    return p_t @ true[:3, :3].T + true[:3, 3] - p_n


#: iBUG rows (0-based) of the inner-lip contour: corner, upper lip, corner, lower lip.
INNER_LIP = np.asarray(INNER_LIPS) - 1

#: The frontal view of the head frame (x right, y up): (x, y, z) -> (x, -y), y down as in images.
FRONT = np.array([[1.0, 0.0], [0.0, -1.0], [0.0, 0.0]])


def template_lip_sides(vertices2d: np.ndarray) -> np.ndarray:
    """(V,) int8 :func:`lip_side` of template vertices (canonical template coordinates): -1 upper
    lip, +1 lower lip, within half a mouth width of the slit; 0 elsewhere."""
    mid = inner_lip_midline(IBUG_CANONICAL[INNER_LIP])
    return lip_side(vertices2d, mid, float(mid[-1, 0] - mid[0, 0]) / 2)


def slit_midline(neutral: Truth) -> np.ndarray:
    """(m, 2) the closed mouth's slit in the :data:`FRONT` view of the head frame, sorted by x.

    At rest the lips meet along a slit whose skin vertices come in coincident pairs, one for
    each lip; those pairs between the inner-lip corners and near them are the slit. A truth with
    fewer than two such pairs (a mouth open at rest) gets the inner-lip landmarks' midline.
    """
    rot, shift = neutral.pose[:3, :3], neutral.pose[:3, 3]
    landmarks = (neutral.landmarks3d[INNER_LIP] - shift) @ rot @ FRONT  # scanner -> head frame
    fallback = inner_lip_midline(landmarks)
    used = np.unique(neutral.faces[neutral.skin_faces])
    v = neutral.vertices[used] @ FRONT
    near = (
        (v[:, 0] > fallback[0, 0])
        & (v[:, 0] < fallback[-1, 0])
        & (np.abs(v[:, 1] - np.interp(v[:, 0], fallback[:, 0], fallback[:, 1])) < 10.0)
    )
    near_3d = neutral.vertices[used[near]]
    pairs = cKDTree(near_3d).query_pairs(1e-6, output_type="ndarray")
    if len(pairs) < 2:
        return fallback
    slit = near_3d[pairs[:, 0]] @ FRONT
    return slit[np.argsort(slit[:, 0])]


def _skin_points(
    neutral_vertices: np.ndarray, neutral: Truth, sides: np.ndarray | None
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The skin point of each valid neutral vertex: groups of (vertices, their skin triangles
    (n, 3), barycentric weights (n, 3)), with the lip sides of :func:`true_motion`."""
    ok = np.isfinite(neutral_vertices).all(axis=1)
    skin = neutral.faces[neutral.skin_faces]
    groups = [(ok, skin)]
    if sides is not None:
        sides = np.asarray(sides)
        if sides.shape != ok.shape:
            raise InputError("truth", f"sides: expected ({len(ok)},) lip sides, got {sides.shape}")
        mid = slit_midline(neutral)
        centre = neutral.vertices[skin].mean(axis=1) @ FRONT
        face_side = lip_side(centre, mid, float(mid[-1, 0] - mid[0, 0]) / 2)
        groups = [(ok & (sides == 0), skin)] + [
            (ok & (sides == s), skin[face_side != -s]) for s in (-1, 1)
        ]
    posed = neutral.posed_vertices()
    points = []
    for where, faces in groups:
        if where.any():
            face, bary, _ = closest_points(posed, faces, neutral_vertices[where])
            points.append((where, faces[face], bary))
    return points


def _at_skin(points: list, shape: tuple, values: np.ndarray) -> np.ndarray:
    """Per-vertex values (``shape``) of a field given on the truth's vertices, at each template
    vertex's skin point (:func:`_skin_points`); NaN where there is none."""
    out = np.full(shape, np.nan)
    for where, tri, bary in points:
        out[where] = np.einsum("qk,qkd->qd", bary, values[tri])
    return out


def true_motions(
    neutral_vertices: np.ndarray,
    neutral: Truth,
    takes: Mapping[str, Truth],
    sides: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """True motion of each template vertex in each take (see :func:`true_motion`).

    The skin point of each neutral vertex (its closest point on the true neutral skin) is found
    once and carried into every take.

    Returns
    -------
    dict take -> (V, 3) float64
        mm in the neutral's scanner frame; NaN where the neutral vertex is invalid.
    """
    points = _skin_points(neutral_vertices, neutral, sides) if takes else []
    rot = neutral.pose[:3, :3]
    return {
        name: _at_skin(points, neutral_vertices.shape, take.vertices - neutral.vertices) @ rot.T
        for name, take in takes.items()
    }


def true_positions(
    neutral_vertices: np.ndarray,
    neutral: Truth,
    takes: Mapping[str, Truth],
    sides: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Where the skin point of each template vertex is in each take (the oracle of a
    correspondence: project it with the take's camera to get the right pixel).

    Parameters as :func:`true_motions` (the skin point and the lip sides are the same).

    Returns
    -------
    dict take -> (V, 3) float64
        mm in the take's frame (``take.pose`` applied: the frame its scan is in); NaN where the
        neutral vertex is invalid.
    """
    points = _skin_points(neutral_vertices, neutral, sides) if takes else []
    return {
        name: _at_skin(points, neutral_vertices.shape, take.vertices) @ take.pose[:3, :3].T
        + take.pose[:3, 3]
        for name, take in takes.items()
    }


def true_motion(
    neutral_vertices: np.ndarray,
    neutral: Truth,
    take: Truth,
    sides: np.ndarray | None = None,
) -> np.ndarray:
    """(V, 3) true motion (mm, neutral scanner frame) of each template vertex; NaN where invalid.

    Parameters
    ----------
    neutral_vertices : (V, 3) float, mm
        The neutral mesh in the neutral's scanner frame.
    neutral, take : Truth
    sides : (V,) int, optional
        The lip each template vertex is on (:func:`template_lip_sides`). At rest the lips meet:
        a vertex on the slit is as close to the lower lip's skin as to the upper lip's, which
        part when the mouth opens; a vertex of one lip is matched only to skin that is not on
        the other. The truth's skin is sided by the slit itself (:func:`slit_midline`), within
        half a mouth width of it. Without ``sides``, the closest skin point whatever the lip.
    """
    return true_motions(neutral_vertices, neutral, {"take": take}, sides)["take"]


def _rel(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> tuple[float, float, float]:
    ok = where & np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    ref = float(np.sqrt(np.mean(np.sum(b[ok] ** 2, axis=1)))) if ok.any() else float("nan")
    err = (
        float(np.sqrt(np.mean(np.sum((a[ok] - b[ok]) ** 2, axis=1)))) if ok.any() else float("nan")
    )
    return err, ref, err / ref if ref > 0 else float("nan")


def split_error(
    motion: np.ndarray, reference: np.ndarray, normals: np.ndarray, where: np.ndarray
) -> dict:
    """RMS of ``motion - reference`` along the surface normal and tangent to it, mm.

    Over the vertices in ``where`` with a finite motion, reference and normal. The normal part
    is a wrong surface; the tangential part a vertex that slid along a right surface.
    """
    n = np.asarray(normals, dtype=np.float64)
    delta = np.asarray(motion, dtype=np.float64) - np.asarray(reference, dtype=np.float64)
    ok = where & np.isfinite(delta).all(axis=1) & np.isfinite(n).all(axis=1)
    if not ok.any():
        return {"normal_rms_mm": float("nan"), "tangential_rms_mm": float("nan")}
    along = np.einsum("vd,vd->v", delta[ok], n[ok])
    tangent = delta[ok] - along[:, None] * n[ok]
    return {
        "normal_rms_mm": float(np.sqrt(np.mean(along**2))),
        "tangential_rms_mm": float(np.sqrt(np.mean(np.sum(tangent**2, axis=1)))),
    }


def material_accuracy(
    motion: np.ndarray, material: np.ndarray, normals: np.ndarray, where: np.ndarray
) -> dict:
    """Error of a motion or displacement field against the material motion of the skin.

    Parameters
    ----------
    motion, material : (V, 3) float
        The field and where each skin point really went, mm (NaN where undefined).
    normals : (V, 3) float
        Unit normals of the neutral mesh.
    where : (V,) bool
        Vertices to measure over.

    Returns
    -------
    dict
        ``material_relative_error`` (RMS error over RMS material motion), ``material_rms_mm``
        (RMS material motion), ``material_rms_error_mm`` and its parts
        ``material_normal_rms_error_mm`` (along the normal) and
        ``material_tangential_rms_error_mm`` (along the surface: sliding), mm.
    """
    err, ref, rel = _rel(motion, material, where)
    split = split_error(motion, material, normals, where)
    return {
        "material_relative_error": rel,
        "material_rms_mm": ref,
        "material_rms_error_mm": err,
        "material_normal_rms_error_mm": split["normal_rms_mm"],
        "material_tangential_rms_error_mm": split["tangential_rms_mm"],
    }


def motion_accuracy(
    motion: np.ndarray,
    motion_raw: np.ndarray,
    ideal: np.ndarray,
    material: np.ndarray,
    suppressed: np.ndarray,
    ideal_processed: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> dict:
    """Errors of the motion over unmasked vertices, relative to the reference motion's RMS.

    Parameters
    ----------
    motion, motion_raw : (V, 3) the pipeline's final and raw motion, mm
    ideal : (V, 3) ideal raw motion (see module docstring)
    material : (V, 3) material motion
    suppressed : (V,) bool, the stencil mask
    ideal_processed : (V, 3), optional
        The ideal motion put through the same mask and smoothing as the pipeline's.
    normals : (V, 3), optional
        Unit surface normals of the neutral mesh (NaN where undefined). With them the error
        against the reference splits into its component along the normal (a wrong surface) and
        the rest, tangent to the surface (a vertex that slid along a right surface).

    Returns
    -------
    dict
        ``relative_error``: final motion vs the ideal motion put through the same mask and
        smoothing (what the data cost; the accuracy goal), with ``rms_error_mm`` and
        ``ideal_rms_mm``; ``raw_relative_error``: raw motion vs raw ideal motion;
        ``unprocessed_relative_error``: final motion vs raw ideal motion (adds what masking and
        smoothing change); against material motion ``material_relative_error`` and
        ``material_rms_mm``; ``masked_true_motion_share``: share of the material motion's energy
        (sum of squared lengths) on vertices the mask suppresses (it should cover still skin only).
        With ``normals``: ``normal_rms_error_mm``, ``tangential_rms_error_mm`` (the two parts of
        ``rms_error_mm``, over unmasked vertices with a normal), ``normal_relative_error``
        (the normal part relative to ``ideal_rms_mm``) and :func:`material_accuracy`'s split of
        the error against the material motion.
    """
    free = ~suppressed
    reference = ideal if ideal_processed is None else ideal_processed
    err, ref, rel = _rel(motion, reference, free)
    _, _, raw_rel = _rel(motion_raw, ideal, free)
    _, _, unproc_rel = _rel(motion, ideal, free)
    ok = np.isfinite(material).all(axis=1)
    energy = np.sum(material[ok] ** 2, axis=1)
    # the headline first: the error against where the skin really went
    if normals is not None:
        out = material_accuracy(motion, material, normals, free)
    else:
        _, mat_ref, mat_rel = _rel(motion, material, free)
        out = {"material_relative_error": mat_rel, "material_rms_mm": mat_ref}
    out |= {
        "relative_error": rel,
        "rms_error_mm": err,
        "ideal_rms_mm": ref,
        "raw_relative_error": raw_rel,
        "unprocessed_relative_error": unproc_rel,
        "masked_true_motion_share": float(energy[suppressed[ok]].sum() / energy.sum())
        if energy.sum() > 0
        else 0.0,
    }
    if normals is not None:
        ideal_split = split_error(motion, reference, normals, free)
        out |= {
            "normal_rms_error_mm": ideal_split["normal_rms_mm"],
            "tangential_rms_error_mm": ideal_split["tangential_rms_mm"],
            "normal_relative_error": ideal_split["normal_rms_mm"] / ref
            if ref > 0
            else float("nan"),
        }
    return out
