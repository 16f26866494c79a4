"""A simulated mesh scanner (structured light / photogrammetry export): a vertex-coloured PLY.

The scan is the articulated head's measured surface (skin, brows, hair, eyes; no mouth cavity,
no pupils), each vertex moved along its normal by Gaussian noise (``noise_mm``), in the
scanner's own frame: the head frame moved by a random rigid motion (``pose_sigma_deg``,
``pose_sigma_mm``). Vertex colours are the albedo lit by the scanner's lamp; with
``skin_texture`` > 0 the skin's albedo carries the subject's freckles and mottling
(:func:`~scan2morph.synth.texture.skin_detail` at each vertex's rest position: the same detail
as the range scanner's, fixed to the skin, sampled once per vertex as a vertex-coloured scan
stores it). Landmarks are the 68 landmark vertices with 3D click noise (``click_noise_mm``),
written as lines ``x y z``.

Truth: ``pose`` maps the head into the mesh's frame; ``K`` and ``landmarks2d`` are NaN (the
virtual camera is chosen at ingest: the evaluation projects with the store's camera).
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from scan2morph.errors import InputError, writing
from scan2morph.geometry import vertex_normals
from scan2morph.jobs import write_npz
from scan2morph.synth.cohort import (
    AIM,
    _check_result,
    _take_result,
    _take_truth,
    articulated_head,
    check_take,
    numeric_params,
)
from scan2morph.synth.convention import landmark_vertices
from scan2morph.synth.features import SEG_BROW, SEG_EYE, SEG_HAIR, SEG_SKIN
from scan2morph.synth.identity import Identity
from scan2morph.synth.scanner import head_pose, shade
from scan2morph.synth.texture import skin_detail, texture_seed

#: Parameters of a synthetic mesh scan, with their defaults.
DEFAULT_MESH_SCAN: dict[str, float] = {
    "noise_mm": 0.1,  # vertex noise along the normal (std)
    "pose_sigma_deg": 10.0,  # random rotation of the scanner's frame, per axis
    "pose_sigma_mm": 50.0,  # random translation of the scanner's frame, per axis
    "click_noise_mm": 0.4,  # landmark clicking noise on the mesh, per coordinate
    "skin_texture": 0.0,  # strength of the skin's freckles and mottling per vertex (0: flat albedo)
}
_KEPT = (SEG_SKIN, SEG_BROW, SEG_HAIR, SEG_EYE)


def mesh_scan_params(params: dict | None = None, source: str = "params") -> dict:
    """:data:`DEFAULT_MESH_SCAN` updated with ``params``, checked (names the key on error)."""
    p = numeric_params(params, DEFAULT_MESH_SCAN, (), source)
    for k, v in p.items():
        if v < 0:
            raise InputError(source, f"params.{k}: expected >= 0, got {v}")
    return p


def skin_albedo(head, seed: int, strength: float) -> np.ndarray:
    """The head's per-vertex albedo with the skin's detail at each skin vertex's rest position.

    Parameters
    ----------
    head : HeadModel
        The subject's head (``vertices`` at rest, mm; ``faces``, ``segment``, ``albedo``).
    seed : int
        The subject's texture seed (:func:`~scan2morph.synth.texture.texture_seed`).
    strength : float
        :func:`~scan2morph.synth.texture.skin_detail`'s strength; 0 gives ``head.albedo``.

    Returns
    -------
    (N, 3) float64
        Albedo in [0, 1]: a vertex of a skin triangle multiplied by the detail factor at its
        rest position, every other vertex (brows, hair, eyes) as it is.
    """
    albedo = np.asarray(head.albedo, dtype=np.float64)
    if strength <= 0:
        return albedo
    skin = np.unique(head.faces[head.segment == SEG_SKIN])
    out = albedo.copy()
    out[skin] = np.clip(albedo[skin] * skin_detail(head.vertices[skin], seed, strength), 0.0, 1.0)
    return out


def make_mesh_take(
    subject: str,
    label: str,
    kind: str,
    take: str,
    seed: int,
    params: dict | None = None,
    identity: Identity | None = None,
    convention: str = "synth",
) -> dict:
    """Simulate one mesh scan of a synthetic subject.

    Parameters
    ----------
    subject, label, kind, take, seed
        As in :func:`~scan2morph.synth.cohort.make_take`.
    params : dict, optional
        Overrides of the mesh scan's parameters.
    identity : Identity, optional
        The face instead of the subject's own (``(seed, subject)``'s); the trainer's.
    convention : str
        Landmark conventions of the truth (``landmarks``, ``landmarks3d``, ``landmarks2d``): one
        of :data:`~scan2morph.synth.convention.CONVENTIONS`, the generator's own by default.
        A mesh has no camera: the ``ibug`` jawline is the silhouette seen from the scanner's
        lamp (in front of the face).

    Returns
    -------
    dict
        ``vertices`` (n, 3) mm, ``faces`` (m, 3), ``colors`` (n, 3) uint8 in the mesh's frame;
        ``landmarks`` (68, 3) mm with click noise; ``truth``; ids.
    """
    p = mesh_scan_params(params, check_take(subject, label, kind, take, seed))
    head, vertices, rng = articulated_head(subject, label, kind, take, seed, identity)
    rot = Rotation.from_rotvec(np.deg2rad(p["pose_sigma_deg"]) * rng.standard_normal(3))
    pose = np.eye(4)
    pose[:3, :3] = rot.as_matrix()
    pose[:3, 3] = p["pose_sigma_mm"] * rng.standard_normal(3)
    # colours: the albedo under the scanner's lamp, facing the face
    lamp = head_pose(rng, 1000.0, 0.0, 0.0, AIM)
    v_lamp = vertices @ lamp[:3, :3].T + lamp[:3, 3]
    albedo = skin_albedo(head, texture_seed(subject, seed), p["skin_texture"])
    colors = shade(albedo, v_lamp, vertex_normals(v_lamp, head.faces, fill=0.0))

    faces = head.faces[np.isin(head.segment, _KEPT)]
    used, inv = np.unique(faces, return_inverse=True)
    normals = vertex_normals(vertices, head.faces, fill=0.0)[used]
    noisy = vertices[used] + p["noise_mm"] * rng.standard_normal(len(used))[:, None] * normals
    v_mesh = noisy @ pose[:3, :3].T + pose[:3, 3]
    lm3 = vertices[landmark_vertices(head, vertices, lamp, convention)] @ pose[:3, :3].T
    lm3 = lm3 + pose[:3, 3]
    clicked = lm3 + p["click_noise_mm"] * rng.standard_normal(lm3.shape)
    camera = {"K": np.full((3, 3), np.nan)}
    truth = _take_truth(head, vertices, pose, camera, lm3, np.full((len(lm3), 2), np.nan))
    images = {
        "vertices": v_mesh,
        "faces": inv.reshape(-1, 3),
        "colors": np.clip(np.rint(colors[used] * 255), 0, 255).astype(np.uint8),
    }
    return _take_result(images, clicked, truth, subject, take, kind, label)


def write_landmarks3d(path: str | PathLike[str], points: np.ndarray) -> None:
    """Write 3D landmarks as lines ``x y z`` (mm, 4 decimals) after a ``#`` header line
    (:func:`scan2morph.io.landmarks.write_landmarks3d`)."""
    from scan2morph.io.landmarks import write_landmarks3d as write

    write(path, points, "iBUG-68 landmarks: x y z in the mesh's frame, mm", ".4f")


def write_mesh_take(
    result: dict,
    mesh_path: str | PathLike[str],
    landmarks_path: str | PathLike[str],
    truth_path: str | PathLike[str],
) -> None:
    """Write a take from :func:`make_mesh_take`: a binary PLY with vertex colours, the 3D
    landmarks and the truth ``.npz``."""
    import trimesh

    keys = ("vertices", "faces", "colors", "landmarks", "truth")
    _check_result(result, keys, str(truth_path), "make_mesh_take")
    mesh = trimesh.Trimesh(
        result["vertices"], result["faces"], vertex_colors=result["colors"], process=False
    )
    with writing(mesh_path):
        Path(mesh_path).write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="binary"))
    write_landmarks3d(landmarks_path, result["landmarks"])
    write_npz(truth_path, result["truth"])


__all__ = [
    "DEFAULT_MESH_SCAN",
    "make_mesh_take",
    "mesh_scan_params",
    "skin_albedo",
    "write_landmarks3d",
    "write_mesh_take",
]
