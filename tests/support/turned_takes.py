"""The real head's takes as range scans of a fixed scanner, the head turning between the neutral
and its takes, and the takes' accuracy in the results.

The real head of the real-data tests (tests/support/real_head.py) as three takes: the neutral, a
viseme ``car1`` (label ``car``: :func:`jaw_drop`, the lower face turned 5 degrees about a jaw
axis near the ears) and an expression ``smile1`` (label ``smile``: :func:`mouth_pull`, the mouth
corners pulled out, up and back by 5 and 4 mm). Each displacement moves the mesh's vertices, and
the texture with them: the skin's material motion is known at every point. Each take is seen by
a fixed range scanner (:data:`SIZE`, :data:`FOCAL_PX` from :data:`DISTANCE_MM`: about 1.9 px per
mm at the face) as XYZ in its camera frame (``.npz``, :data:`RANGE_NOISE_MM` along each pixel's
ray) and colour (``.png``, with tests/support/real_user.py's image noise), the neutral from
:data:`NEUTRAL_VIEW`, its takes from a view turned by a variant's yaw (``same``: not turned;
``yaw8``: 8 degrees), with the hand annotation's 68 points (tests/support/lps_landmarks.py)
moved with the skin and projected as landmark files. A sheet holds, per variant, one subject
that gives the landmark files (``<variant>_clicked``) and one that leaves them out
(``<variant>_detected``). Used by ``benchmarks/bench_turned_takes.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
import yaml
from PIL import Image
from scipy.spatial.transform import Rotation

from scan2morph.align import invert, rotation_angle_deg, transform_points
from scan2morph.evaluate.motion import material_accuracy
from scan2morph.geometry import vertex_normals
from scan2morph.io import write_pts
from scan2morph.io.mesh_scan import render_mesh
from scan2morph.render.scene import look_at
from scan2morph.store import paths, read_part
from scan2morph.store.warnings import landmark_source, text_value
from scan2morph.synth.scanner import backproject, camera_matrix, project
from tests.support.lps_landmarks import LANDMARKS_MM
from tests.support.real_user import noisy_color

#: The range scanner's image (width, height), px.
SIZE = (640, 480)
#: From the scanner to its aiming point (40 mm behind the nose tip, 5 mm above it), mm.
DISTANCE_MM = 900.0
#: The scanner's focal length, px: about 1.9 px per mm at the face.
FOCAL_PX = 1.9 * DISTANCE_MM
#: The range scanner's noise along each pixel's ray, mm.
RANGE_NOISE_MM = 0.15
#: The neutral's view: (yaw, pitch) of the scanner about the head, degrees.
NEUTRAL_VIEW = (4.0, 2.0)
#: The takes: (take, kind, label).
TAKES = (
    ("neutral", "neutral", "neutral"),
    ("car1", "viseme", "car"),
    ("smile1", "expression", "smile"),
)
#: A subject per variant and landmark source: with the landmark files, and without.
SOURCES = ("clicked", "detected")
#: The jaw drop's angle, degrees.
JAW_DEG = 5.0
#: The mouth corners' pull (iBUG 49, iBUG 55), mm.
PULL_MM = (5.0, 4.0)
#: The pull's direction at either corner in the model frame, its x toward the corner's side:
#: out (away from the nose's midline), up, and back into the face.
PULL_DIRECTION = np.array([0.75, 0.55, -0.35])
#: The pull's Gaussian falloff, standard deviation in the face's plane, mm.
PULL_SIGMA_MM = 10.0
#: iBUG indices (0-based) of the mouth corners.
MOUTH_CORNERS = (48, 54)


def _smoothstep(lo: float, hi: float, x: np.ndarray) -> np.ndarray:
    """0 below ``lo``, 1 above ``hi``, a cubic step between."""
    t = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def jaw_drop(head, points: np.ndarray, deg: float = JAW_DEG) -> np.ndarray:
    """A jaw drop's displacement at model-frame points.

    The lower face turns by ``deg`` about an axis along the model's x through a hinge 5 mm
    below the nose tip and 15 mm in front of the ears (the chin down and back), weighted 1 from
    6 mm below the mouth corners and 0 from 4 mm above them, over the face (fading 45-70 mm to
    the side of the nose, 10-40 mm in front of the ears) and fading out on the neck.

    Parameters
    ----------
    head
        :func:`tests.support.lps_landmarks.load_real_head`'s.
    points : (n, 3) float
        Model frame, mm.
    deg : float
        The jaw's turn, degrees.

    Returns
    -------
    (n, 3) float64
        Model frame, mm.
    """
    p = np.asarray(points, dtype=np.float64)
    mouth_y = LANDMARKS_MM[list(MOUTH_CORNERS), 1].mean()
    weight = 1.0 - _smoothstep(mouth_y - 6.0, mouth_y + 4.0, p[:, 1])
    weight *= 1.0 - _smoothstep(45.0, 70.0, np.abs(p[:, 0] - head.nose[0]))
    weight *= _smoothstep(head.ear_z + 10.0, head.ear_z + 40.0, p[:, 2])
    weight *= _smoothstep(head.chin_y - 45.0, head.chin_y - 15.0, p[:, 1])
    hinge = np.array([0.0, head.nose[1] - 5.0, head.ear_z + 15.0])
    turn = Rotation.from_euler("x", deg, degrees=True).as_matrix()
    return weight[:, None] * ((p - hinge) @ turn.T + hinge - p)


def mouth_pull(head, points: np.ndarray, mm: tuple[float, float] = PULL_MM) -> np.ndarray:
    """A smile's displacement at model-frame points: each mouth corner (the annotation's) pulled
    out, up and back (:data:`PULL_DIRECTION`) by its amplitude with a Gaussian falloff
    (:data:`PULL_SIGMA_MM`) over the face (fading in 20-50 mm in front of the ears).

    Parameters
    ----------
    head
        :func:`tests.support.lps_landmarks.load_real_head`'s.
    points : (n, 3) float
        Model frame, mm.
    mm : (2,) float
        The pull at iBUG 49 and at iBUG 55, mm.

    Returns
    -------
    (n, 3) float64
        Model frame, mm.
    """
    p = np.asarray(points, dtype=np.float64)
    front = _smoothstep(head.ear_z + 20.0, head.ear_z + 50.0, p[:, 2])
    out = np.zeros_like(p)
    for corner, amplitude in zip(MOUTH_CORNERS, mm, strict=True):
        centre = LANDMARKS_MM[corner]
        side = np.sign(centre[0] - head.nose[0])
        r2 = np.sum((p[:, :2] - centre[:2]) ** 2, axis=1)
        g = amplitude * front * np.exp(-r2 / (2.0 * PULL_SIGMA_MM**2))
        out += g[:, None] * (PULL_DIRECTION * [side, 1.0, 1.0])
    return out


#: Each take's displacement (model frame, mm): None for the neutral.
DISPLACEMENTS = {"neutral": None, "car1": jaw_drop, "smile1": mouth_pull}


def displacement(head, take: str, points: np.ndarray) -> np.ndarray:
    """A take's displacement (n, 3) at model-frame points (n, 3), mm (0 for the neutral)."""
    field = DISPLACEMENTS[take]
    return np.zeros_like(points, dtype=np.float64) if field is None else field(head, points)


def camera_pose(head, yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """The scanner's pose (4, 4), model frame -> camera frame (OpenCV axes: x right, y down, z
    forward), aimed at a point 40 mm behind the nose tip and 5 mm above it from
    :data:`DISTANCE_MM`, its direction turned by yaw (about the model's up axis) and pitch,
    degrees."""
    target = head.nose + [0.0, 5.0, -40.0]
    back = Rotation.from_euler("yx", [yaw_deg, pitch_deg], degrees=True).apply([0.0, 0.0, 1.0])
    opengl = look_at(target + DISTANCE_MM * back, target, np.array([0.0, 1.0, 0.0]))
    return np.diag([1.0, -1.0, -1.0, 1.0]) @ invert(opengl)


def _textured(head, vertices: np.ndarray) -> trimesh.Trimesh:
    """The head's mesh at ``vertices`` (V, 3) with its colour map (a white material: the map's
    colours as they are)."""
    material = trimesh.visual.material.SimpleMaterial(
        image=Image.fromarray(head.texture), diffuse=[255, 255, 255, 255]
    )
    visual = trimesh.visual.TextureVisuals(uv=head.uv, material=material)
    return trimesh.Trimesh(vertices, head.faces, visual=visual, process=False)


def _range_take(head, take: str, pose: np.ndarray, folder: Path, rng: np.random.Generator):
    """A take seen by the range scanner at ``pose`` (model -> camera, (4, 4)): XYZ (camera frame,
    mm, noise along each pixel's ray), colour and the annotation moved with the skin, projected,
    written to ``folder``; the sheet's cells (file names)."""
    K = camera_matrix(*SIZE, FOCAL_PX)
    moved = head.vertices + displacement(head, take, head.vertices)
    color, depth = render_mesh(_textured(head, moved), K, pose, SIZE)
    xyz = backproject(K, depth)
    length = np.linalg.norm(xyz, axis=2, keepdims=True)
    xyz = xyz * (1.0 + RANGE_NOISE_MM * rng.standard_normal(length.shape) / length)
    np.savez_compressed(folder / "xyz.npz", xyz=xyz.astype(np.float32))
    Image.fromarray(noisy_color(color, rng)).save(folder / "color.png")
    marks = LANDMARKS_MM + displacement(head, take, LANDMARKS_MM)
    write_pts(folder / "landmarks.pts", project(K, transform_points(pose, marks)))
    return {"xyz": "xyz.npz", "color": "color.png", "landmarks": "landmarks.pts"}


def variant_name(yaw_deg: float) -> str:
    """A variant's name (a subject id's first part) for its takes' turn from the neutral's view:
    ``same`` for none, else ``yaw<degrees>`` (``yaw8``, ``yaw-4``, ``yaw2p5``)."""
    return "same" if yaw_deg == 0 else f"yaw{yaw_deg:g}".replace(".", "p")


def subjects(turns) -> list[str]:
    """The sheet's subjects for the takes' turns ``turns`` (degrees): a variant (each turn's
    :func:`variant_name`) and a landmark source (:data:`SOURCES`) each."""
    return [f"{variant_name(t)}_{s}" for t in turns for s in SOURCES]


def write_takes(head, work: Path, seed: int, turns=(0.0, 8.0)) -> dict[str, dict[str, np.ndarray]]:
    """Every variant's takes as range scans, the sheet (``work/subjects.tsv``: the subjects of
    :func:`subjects`) and its config (``work/turned.yaml``).

    Parameters
    ----------
    head
        :func:`tests.support.lps_landmarks.load_real_head`'s.
    work : Path
        The working directory.
    seed : int
        Seed of the sensors' noise.
    turns : sequence of float
        Each variant's yaw of its takes' view from the neutral's, degrees.

    Returns
    -------
    dict variant -> dict take -> (4, 4) float64
        Each take's pose, model frame -> the take's (camera) frame.
    """
    rng = np.random.default_rng(seed)
    poses: dict[str, dict[str, np.ndarray]] = {}
    cells: dict[tuple[str, str], dict[str, str]] = {}
    for turn in turns:
        variant = variant_name(turn)
        poses[variant] = {}
        for take, kind, _ in TAKES:
            yaw, pitch = NEUTRAL_VIEW
            pose = camera_pose(head, yaw + (0.0 if kind == "neutral" else turn), pitch)
            folder = work / "scans" / variant / take
            folder.mkdir(parents=True, exist_ok=True)
            files = _range_take(head, take, pose, folder, rng)
            cells[variant, take] = {k: f"scans/{variant}/{take}/{f}" for k, f in files.items()}
            poses[variant][take] = pose
    header = ["subject", "take", "kind", "label", "modality", "xyz", "color", "landmarks"]
    rows = [header]
    for subject in subjects(turns):
        variant, source = subject.rsplit("_", 1)
        for take, kind, label in TAKES:
            given = cells[variant, take] | ({"landmarks": ""} if source == "detected" else {})
            rows.append([subject, take, kind, label, "range", *map(given.get, header[5:])])
    (work / "subjects.tsv").write_text("\n".join("\t".join(r) for r in rows) + "\n")
    config = {"subjects": str(work / "subjects.tsv"), "synthetic": {"subjects": 0}}
    (work / "turned.yaml").write_text(yaml.safe_dump(config))
    return poses


def _take_accuracy(head, store: dict, take: str, kind: str, poses: dict, model, normals):
    """One take's alignment and material error in a subject's store (``model``: the neutral's
    template vertices mapped to the model frame, (V, 3) mm; ``normals``: the neutral mesh's,
    (V, 3))."""
    if paths.failed(take, "reason") in store:
        return {"left_out": text_value(store[paths.failed(take, "reason")])}
    neutral = poses["neutral"]
    true_transform = neutral @ invert(poses[take])  # take frame -> neutral frame
    got = np.asarray(store[paths.align(take, "transform")], dtype=np.float64)
    key = (
        paths.viseme(take, "motion") if kind == "viseme" else paths.expression(take, "displacement")
    )
    field = np.asarray(store[key], dtype=np.float64)
    truth = displacement(head, take, model) @ neutral[:3, :3].T
    ok = np.isfinite(field).all(axis=1) & np.isfinite(truth).all(axis=1)
    error = material_accuracy(field, truth, normals, ok)
    return {
        "rotation_deg": float(rotation_angle_deg((got @ invert(true_transform))[:3, :3])),
        "motion_rms_mm": error["material_rms_mm"],
        "material_relative_error": error["material_relative_error"],
        "vertices": int(ok.sum()),
        "landmark_source": landmark_source(store, take),
        "doubtful": text_value(store.get(paths.landmark_info(take, "doubtful"), "")),
    }


def evaluate(head, work: Path, subject: str, poses: dict[str, dict[str, np.ndarray]]) -> dict:
    """Each non-neutral take's accuracy in a subject's store (``work/results/<subject>``).

    The truth at each of the neutral's template vertices (the neutral's frame) is the take's
    displacement at the vertex mapped back to the model frame, turned into the neutral's frame.

    Parameters
    ----------
    head
        :func:`tests.support.lps_landmarks.load_real_head`'s.
    work : Path
        The working directory.
    subject : str
        Of :func:`subjects`.
    poses : dict
        :func:`write_takes`'s.

    Returns
    -------
    dict take -> dict
        ``rotation_deg`` (the alignment's rotation error, degrees), ``motion_rms_mm`` (the true
        motion's RMS), ``material_relative_error`` (RMS of the measured displacement's error over
        ``motion_rms_mm``), ``vertices`` (the valid template vertices it is over),
        ``landmark_source`` and ``doubtful`` (the take's landmarks); ``{"left_out": reason}``
        for a take its subject left out.
    """
    store = read_part(work / "results" / subject / f"{subject}.h5")
    take_poses = poses[subject.rsplit("_", 1)[0]]
    vertices = np.asarray(store[paths.mesh("neutral", "vertices")], dtype=np.float64)
    model = transform_points(invert(take_poses["neutral"]), vertices)
    normals = vertex_normals(vertices, np.asarray(store[paths.template("faces")]))
    return {
        take: _take_accuracy(head, store, take, kind, take_poses, model, normals)
        for take, kind, _ in TAKES
        if kind != "neutral"
    }
