"""The real head written as a user's scans, and the smile's accuracy in the results.

The real head of the real-data tests (tests/support/real_head.py) as a neutral and a smiling
take (:func:`~tests.support.real_head.smile_displacement` moves the vertices, and the texture
with them: the skin's material motion is known at every point), each an OBJ with its colour map
in a scanner frame of its own, with the hand annotation's 68 points moved with it
(tests/support/lps_landmarks.py) as its landmark file; each OBJ also scanned as a range scan
(XYZ, colour, 0.1 mm noise along the rays) and as an RGB-D take (16-bit depth in 1 mm units with
a depth camera's noise, 600 mm away at 1 mm per pixel), their landmarks projected onto their
grids; and the head seen by the real-data tests' stereo rig, which stays where it is while the head
moves (its speckle is projected from the rig: it does not move with the skin), its takes'
colour once the left image and once the left camera's texture shot (the projector off). A sheet
holds, per scan, one subject that gives the landmark files (``*_clicked``) and one that leaves
them out (``*_detected``). Used by ``benchmarks/bench_real_user.py`` and
``tests/workflow/test_real_user.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
import yaml
from PIL import Image
from scipy.spatial.transform import Rotation

from scan2morph.align import invert, transform_points
from tests.support.lps_landmarks import LANDMARKS_MM
from tests.support.real_head import smile_displacement

#: The scans written: a modality each, and ``stereo-shot``, the stereo takes with the left
#: camera's texture shot (the projector off) as their colour.
MODALITIES = ("mesh", "range", "rgbd", "stereo", "stereo-shot")
#: A subject per scan and landmark source: with the landmark files, and without.
SUBJECTS = tuple(f"{m}_{v}" for m in MODALITIES for v in ("clicked", "detected"))
#: The scanner frames' motion: standard deviation of the rotation per axis (degrees) and of the
#: translation per axis (mm).
POSE_SIGMA = (3.0, 5.0)
#: The range scanner's noise along each pixel's ray (the synthetic range scanner's default), mm;
#: its grid is the mesh take's virtual camera (about 0.5 mm per pixel).
RANGE_NOISE_MM = 0.1
#: The depth camera (the colour camera with it): 600 mm from the face, 1 mm per pixel; its depth
#: noise 2 mm x (z / 1 m)^2 in 1 mm units (the synthetic sensor's defaults).
RGBD_CAMERA = {"distance_mm": 600.0, "pixel_mm": 1.0}
RGBD_NOISE_MM_AT_1M = 2.0
#: The colour sensors' noise, grey levels.
IMAGE_NOISE = 1.5
#: The takes: (take, kind, label).
TAKES = (("neutral", "neutral", "neutral"), ("smile", "expression", "smile"))


def _pose(rng: np.random.Generator) -> np.ndarray:
    """A scanner frame: model frame -> scan frame, (4, 4)."""
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(np.deg2rad(POSE_SIGMA[0]) * rng.normal(size=3)).as_matrix()
    pose[:3, 3] = POSE_SIGMA[1] * rng.normal(size=3)
    return pose


def _smile_at(points: np.ndarray, nose: np.ndarray) -> np.ndarray:
    """The smile's displacement (n, 3) at model-frame points (n, 3), mm."""
    return smile_displacement(points[:, 0] - nose[0], points[:, 1] - nose[1])


def noisy_color(color: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``color`` (H, W, 3) uint8 with the colour sensors' noise (:data:`IMAGE_NOISE` grey levels,
    ``rng``), rounded and clipped."""
    noisy = color.astype(np.float64) + IMAGE_NOISE * rng.standard_normal(color.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def _range_take(obj: Path, marks: Path, folder: Path, rng: np.random.Generator) -> dict:
    """The OBJ scanned by a range scanner: XYZ (.npz, the scan frame) with noise along each
    pixel's ray, colour (.png) and the landmarks (.pts) on its grid; the sheet's cells."""
    import cv2

    from scan2morph.io import write_pts
    from scan2morph.io.mesh_scan import read_mesh_take

    take = read_mesh_take(obj, None, marks)
    cam = transform_points(take.pose, take.xyz)
    length = np.linalg.norm(cam, axis=2, keepdims=True)
    cam = cam * (1.0 + RANGE_NOISE_MM * rng.standard_normal(length.shape) / length)
    xyz = transform_points(invert(take.pose), cam)
    np.savez_compressed(folder / "range.npz", xyz=xyz.astype(np.float32))
    cv2.imwrite(str(folder / "range.png"), noisy_color(take.color, rng)[..., ::-1])
    write_pts(folder / "range.pts", take.landmarks)
    return {"xyz": "range.npz", "color": "range.png", "landmarks": "range.pts"}


def _rgbd_take(obj: Path, marks: Path, folder: Path, rng: np.random.Generator):
    """The OBJ seen by a depth camera: 16-bit depth (1 mm units) with depth-dependent noise,
    colour, intrinsics YAML and landmarks (.pts); the sheet's cells and the scan frame ->
    camera pose (4, 4)."""
    import cv2

    from scan2morph.io import write_pts
    from scan2morph.io.mesh_scan import read_mesh_take

    take = read_mesh_take(obj, None, marks, RGBD_CAMERA)
    z = transform_points(take.pose, take.xyz)[..., 2]
    z = z + RGBD_NOISE_MM_AT_1M * (z / 1000.0) ** 2 * rng.standard_normal(z.shape)
    depth = np.where(np.isfinite(z), np.rint(z), 0).astype(np.uint16)
    cv2.imwrite(str(folder / "depth.png"), depth)
    cv2.imwrite(str(folder / "color.png"), noisy_color(take.color, rng)[..., ::-1])
    (fx, _, cx), (_, fy, cy) = take.K[:2].tolist()
    intrinsics = dict(width=take.size[0], height=take.size[1], fx=fx, fy=fy, cx=cx, cy=cy)
    (folder / "intrinsics.yaml").write_text(yaml.safe_dump(intrinsics | {"depth_scale_mm": 1.0}))
    write_pts(folder / "rgbd.pts", take.landmarks)
    cells = {"depth": "depth.png", "color": "color.png", "intrinsics": "intrinsics.yaml"}
    return cells | {"landmarks": "rgbd.pts"}, take.pose


def _stereo_take(
    head, moved: np.ndarray, rig: list, folder: Path, seed: int, lm: np.ndarray, shot: bool
):
    """The head, its vertices at ``moved`` (model frame, mm), seen by the real-data tests' stereo
    rig (``rig``, fixed while the head moves: the speckle is projected from it, so it does not
    move with the skin): both images, the calibration and the landmarks ``lm`` (68, 3) (model
    frame) on the left image, and with ``shot`` the left camera's texture shot (``shot.png``,
    the sheet cells' ``color``); the sheet's cells and the model -> left camera pose (4, 4)."""
    import cv2

    from scan2morph.io import write_pts
    from scan2morph.io.calibration import write_stereo_calibration
    from tests.unit import test_realdata as rd

    pair = rd.render_stereo_pair(rd._moved(head, moved), seed, rig, texture_shot=shot)
    cells = {"left": "left.png", "right": "right.png", "calibration": "calib.yaml"}
    if shot:
        cv2.imwrite(str(folder / "shot.png"), pair.texture[..., ::-1])
        cells["color"] = "shot.png"
    cv2.imwrite(str(folder / "left.png"), pair.left[..., ::-1])
    cv2.imwrite(str(folder / "right.png"), pair.right[..., ::-1])
    write_stereo_calibration(folder / "calib.yaml", pair.calib)
    left = rig[0]  # camera -> scanner rotation R, centre C
    pose = np.eye(4)
    pose[:3, :3] = left["R"].T @ head.R_w
    pose[:3, 3] = left["R"].T @ (head.t_w - left["C"])
    cam = transform_points(pose, lm)
    px, _ = cv2.projectPoints(cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), left["K"], left["D"])
    write_pts(folder / "stereo.pts", px.reshape(-1, 2))
    return cells | {"landmarks": "stereo.pts"}, pose


def write_scans(
    head, work: Path, seed: int, modalities: tuple[str, ...] = MODALITIES
) -> dict[str, dict[str, np.ndarray]]:
    """The neutral and the smile as a user's scans in each of ``modalities`` (the mesh scans
    always: the others are scanned from them), the sheet (``work/subjects.tsv``: those of
    :data:`SUBJECTS`) and its config (``work/real.yaml``).

    Parameters
    ----------
    head
        :func:`tests.support.lps_landmarks.load_real_head`'s.
    work : Path
        The working directory.
    seed : int
        Seed of the scanner frames and of the sensors' noise.
    modalities : tuple of str
        Of :data:`MODALITIES`.

    Returns
    -------
    dict scan (of :data:`MODALITIES`) -> dict take -> (4, 4) float64
        Each take's pose, model frame -> the take's frame (the mesh's and the range scan's
        scanner frame; the depth camera's and the left camera's frame).
    """
    from scan2morph.synth.mesh_scan import write_landmarks3d

    rng = np.random.default_rng(seed)
    texture = Image.fromarray(head.texture)
    poses: dict[str, dict[str, np.ndarray]] = {m: {} for m in ("mesh", *modalities)}
    cells: dict[tuple[str, str], dict[str, str]] = {}
    from tests.unit import test_realdata as rd

    rig = rd._rig(head)  # the stereo rig stays where it is for both takes
    wanted = set(modalities)
    for take_number, (take, _, _) in enumerate(TAKES):
        pose = _pose(rng)
        v, lm = head.vertices, LANDMARKS_MM
        if take == "smile":
            v, lm = v + _smile_at(v, head.nose), lm + _smile_at(lm, head.nose)
        visual = trimesh.visual.TextureVisuals(uv=head.uv, image=texture)
        folder = work / "scans" / take
        folder.mkdir(parents=True, exist_ok=True)
        obj, marks = folder / f"{take}.obj", folder / f"{take}.txt"
        scanned, scanned_lm = transform_points(pose, v), transform_points(pose, lm)
        trimesh.Trimesh(scanned, head.faces, visual=visual, process=False).export(obj)
        write_landmarks3d(marks, scanned_lm)
        cells["mesh", take] = {"mesh": obj.name, "landmarks": marks.name}
        poses["mesh"][take] = pose
        if "range" in wanted:
            cells["range", take] = _range_take(obj, marks, folder, rng)
            poses["range"][take] = pose
        if "rgbd" in wanted:
            cells["rgbd", take], camera = _rgbd_take(obj, marks, folder, rng)
            poses["rgbd"][take] = camera @ pose
        stereo = wanted & {"stereo", "stereo-shot"}
        if stereo:  # the rig sees the head moved by its scanner pose; one render serves both
            shot = "stereo-shot" in stereo
            both, left = _stereo_take(
                head, scanned, rig, folder, seed + take_number, scanned_lm, shot
            )  # fmt: skip
            plain = {k: f for k, f in both.items() if k != "color"}  # the left image's colour
            for s in stereo:
                cells[s, take] = both if s == "stereo-shot" else plain
                poses[s][take] = left @ pose
    header = ["subject", "take", "kind", "label", "modality", "mesh", "xyz", "color", "depth"]
    header += ["intrinsics", "left", "right", "calibration", "landmarks"]
    rows = []
    for subject in (s for s in SUBJECTS if s.split("_")[0] in wanted):
        scan, source = subject.split("_")
        modality = scan.split("-")[0]
        for take, kind, label in TAKES:
            given = {k: f"scans/{take}/{f}" for k, f in cells[scan, take].items()}
            if source == "detected":
                given["landmarks"] = ""
            rows.append(
                [subject, take, kind, label, modality, *(given.get(c, "") for c in header[5:])]
            )
    (work / "subjects.tsv").write_text("\n".join("\t".join(r) for r in [header, *rows]) + "\n")
    config = {"subjects": str(work / "subjects.tsv"), "synthetic": {"subjects": 0}}
    (work / "real.yaml").write_text(yaml.safe_dump(config))
    return poses


def evaluate(head, work: Path, subject: str, poses: dict[str, dict[str, np.ndarray]]) -> dict:
    """The smile's alignment and material error in a subject's store; ``{"left_out": reason}``
    when the subject left the smile out (the stage's message). The error's split along the
    neutral's normals and across them is over the vertices that have a normal (a folded
    template's may not)."""
    from scan2morph.align import rotation_angle_deg
    from scan2morph.geometry import vertex_normals
    from scan2morph.store import paths, read_part

    store = read_part(work / "results" / subject / f"{subject}.h5")
    if paths.failed("smile", "reason") in store:  # the take was left out of its subject
        reason = np.asarray(store[paths.failed("smile", "reason")]).item()
        return {"left_out": reason.decode() if isinstance(reason, bytes) else str(reason)}
    a, b = (poses[subject.split("_")[0]][take] for take in ("neutral", "smile"))
    true_transform = a @ np.linalg.inv(b)  # smile scan frame -> neutral scan frame
    got = np.asarray(store[paths.align("smile", "transform")], dtype=np.float64)
    delta = got @ np.linalg.inv(true_transform)
    nv = np.asarray(store[paths.mesh("neutral", "vertices")], dtype=np.float64)
    faces = np.asarray(store[paths.template("faces")])
    model = transform_points(invert(a), nv)  # neutral scan frame -> model frame
    truth = _smile_at(model, head.nose) @ a[:3, :3].T
    field = np.asarray(store[paths.expression("smile", "displacement")], dtype=np.float64)
    ok = np.isfinite(field).all(axis=1) & np.isfinite(nv).all(axis=1)
    centre = nv[np.isfinite(nv).all(axis=1)].mean(axis=0)
    err = field[ok] - truth[ok]
    # a vertex whose faces fold over one another has no normal: the split leaves it out
    normals = vertex_normals(nv, faces)[ok]
    has = np.isfinite(normals).all(axis=1)
    along = np.einsum("ij,ij->i", err[has], normals[has])
    rms = float(np.sqrt(np.mean(np.sum(truth[ok] ** 2, axis=1))))
    return {
        "rotation_deg": float(rotation_angle_deg(delta[:3, :3])),
        # at the face (an RGB-D take's frame has its origin at the camera, 600 mm away)
        "translation_mm": float(np.linalg.norm(delta[:3, :3] @ centre + delta[:3, 3] - centre)),
        "motion_rms_mm": rms,
        "material_relative_error": float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) / rms,
        "normal_mm": float(np.sqrt(np.mean(along**2))),
        "tangential_mm": float(np.sqrt(np.mean(np.sum(err[has] ** 2, axis=1) - along**2))),
        "vertices": int(ok.sum()),
        "warnings": [str(w) for w in np.asarray(store.get(paths.warnings("message"), []))],
    }
