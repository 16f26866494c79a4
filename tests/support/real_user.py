"""The real head written as a user's mesh scans, and the smile's accuracy in the results.

The real head of the real-data tests (tests/support/real_head.py) as a neutral and a smiling
take (:func:`~tests.support.real_head.smile_displacement` moves the vertices, and the texture
with them: the skin's material motion is known at every point), each an OBJ with its colour map
in a scanner frame of its own, with the hand annotation's 68 points moved with it
(tests/support/lps_landmarks.py) as its landmark file; a sheet with one subject that gives the
landmark files (``clicked``) and one that leaves them out (``detected``). Used by
``benchmarks/bench_real_user.py`` and ``tests/workflow/test_real_user.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
import yaml
from PIL import Image
from scipy.spatial.transform import Rotation

from tests.support.lps_landmarks import LANDMARKS_MM
from tests.support.real_head import smile_displacement

#: The subjects of the sheet: with the landmark files, and without.
SUBJECTS = ("clicked", "detected")
#: The scanner frames' motion: standard deviation of the rotation per axis (degrees) and of the
#: translation per axis (mm).
POSE_SIGMA = (3.0, 5.0)


def _pose(rng: np.random.Generator) -> np.ndarray:
    """A scanner frame: model frame -> scan frame, (4, 4)."""
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(np.deg2rad(POSE_SIGMA[0]) * rng.normal(size=3)).as_matrix()
    pose[:3, 3] = POSE_SIGMA[1] * rng.normal(size=3)
    return pose


def _moved(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    return points @ pose[:3, :3].T + pose[:3, 3]


def _smile_at(points: np.ndarray, nose: np.ndarray) -> np.ndarray:
    """The smile's displacement (n, 3) at model-frame points (n, 3), mm."""
    return smile_displacement(points[:, 0] - nose[0], points[:, 1] - nose[1])


def write_scans(head, work: Path, seed: int) -> dict[str, np.ndarray]:
    """The neutral and the smile as textured OBJs with landmark files, the sheet
    (``work/subjects.tsv``) and its config (``work/real.yaml``).

    Parameters
    ----------
    head
        :func:`tests.support.lps_landmarks.load_real_head`'s.
    work : Path
        The working directory.
    seed : int
        Seed of the scanner frames.

    Returns
    -------
    dict take -> (4, 4) float64
        Each take's scanner pose (model frame -> scan frame).
    """
    from scan2morph.synth.mesh_scan import write_landmarks3d

    rng = np.random.default_rng(seed)
    texture = Image.fromarray(head.texture)
    poses = {}
    for take in ("neutral", "smile"):
        poses[take] = pose = _pose(rng)
        v, lm = head.vertices, LANDMARKS_MM
        if take == "smile":
            v, lm = v + _smile_at(v, head.nose), lm + _smile_at(lm, head.nose)
        visual = trimesh.visual.TextureVisuals(uv=head.uv, image=texture)
        folder = work / "scans" / take
        folder.mkdir(parents=True, exist_ok=True)
        mesh = trimesh.Trimesh(_moved(v, pose), head.faces, visual=visual, process=False)
        mesh.export(folder / f"{take}.obj")
        write_landmarks3d(folder / f"{take}.txt", _moved(lm, pose))
    header = ["subject", "take", "kind", "label", "modality", "mesh", "landmarks"]
    rows = []
    for subject in SUBJECTS:
        for take, kind, label in (
            ("neutral", "neutral", "neutral"),
            ("smile", "expression", "smile"),
        ):
            marks = f"scans/{take}/{take}.txt" if subject == "clicked" else ""
            rows.append([subject, take, kind, label, "mesh", f"scans/{take}/{take}.obj", marks])
    (work / "subjects.tsv").write_text("\n".join("\t".join(r) for r in [header, *rows]) + "\n")
    config = {"subjects": str(work / "subjects.tsv"), "synthetic": {"subjects": 0}}
    (work / "real.yaml").write_text(yaml.safe_dump(config))
    return poses


def evaluate(head, work: Path, subject: str, poses: dict[str, np.ndarray]) -> dict:
    """The smile's alignment and material error in a subject's store."""
    from scan2morph.align import rotation_angle_deg
    from scan2morph.geometry import vertex_normals
    from scan2morph.store import paths, read_part

    store = read_part(work / "results" / subject / f"{subject}.h5")
    a, b = poses["neutral"], poses["smile"]
    true_transform = a @ np.linalg.inv(b)  # smile scan frame -> neutral scan frame
    got = np.asarray(store[paths.align("smile", "transform")], dtype=np.float64)
    delta = got @ np.linalg.inv(true_transform)
    nv = np.asarray(store[paths.mesh("neutral", "vertices")], dtype=np.float64)
    faces = np.asarray(store[paths.template("faces")])
    model = (nv - a[:3, 3]) @ a[:3, :3]  # neutral scan frame -> model frame
    truth = _smile_at(model, head.nose) @ a[:3, :3].T
    field = np.asarray(store[paths.expression("smile", "displacement")], dtype=np.float64)
    ok = np.isfinite(field).all(axis=1) & np.isfinite(nv).all(axis=1)
    err = field[ok] - truth[ok]
    normals = vertex_normals(nv, faces)[ok]
    along = np.einsum("ij,ij->i", err, normals)
    rms = float(np.sqrt(np.mean(np.sum(truth[ok] ** 2, axis=1))))
    return {
        "rotation_deg": float(rotation_angle_deg(delta[:3, :3])),
        "translation_mm": float(np.linalg.norm(delta[:3, 3])),
        "motion_rms_mm": rms,
        "material_relative_error": float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) / rms,
        "normal_mm": float(np.sqrt(np.mean(along**2))),
        "tangential_mm": float(np.sqrt(np.mean(np.sum(err**2, axis=1) - along**2))),
        "vertices": int(ok.sum()),
        "warnings": [str(w) for w in np.asarray(store.get(paths.warnings("message"), []))],
    }
