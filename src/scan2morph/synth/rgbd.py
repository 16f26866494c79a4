"""A simulated RGB-D sensor (RealSense-like): a depth camera and a colour camera beside it.

The head sits ``distance_mm`` in front of the depth camera with the random pose of a range take;
a flat wall stands ``wall_mm`` behind the camera (0: no wall, the background has no data). The
colour camera is ``baseline_mm`` to the side of the depth camera and turned by
``color_rotation_deg`` about its vertical axis (``x_color = R x_depth + T``).

The depth image is the rendered camera Z (:func:`~scan2morph.synth.scanner.render`) with the
defects of a depth camera, all seeded: no data from the mouth cavity and the pupils; **flying
pixels** at depth edges (a share ``flying_fraction`` of the pixels whose 3 x 3 neighbourhood
spans more than ``edge_jump_mm`` gets a depth between the near and the far surface, as a sensor
averaging both sides returns); **depth-dependent noise** along Z with standard deviation
``noise_mm_at_1m`` (z / 1 m)^2 (the error of triangulating sensors grows with the square of the
distance); **quantisation** to ``depth_unit_mm`` (the PNG's units, written as
``depth_scale_mm``). The colour image is rendered from the colour camera (plus sensor noise).

Truth: ``pose`` maps the head into the depth camera's frame (the take's frame), ``K`` is the
colour camera's (the landmarks' and the range image's grid), ``color_from_scanner`` (4, 4) the
depth -> colour transform, ``xyz_true`` (H, W, 3) the exact surface point of every colour pixel
in the depth camera's frame and ``segment`` its ``SEG_*`` code. A take of several depth
frames (``frames``) also has ``frame_poses`` (N, 4, 4), each frame's head -> depth camera pose
(the first is ``pose``): the head turns a little about its origin between frames.
"""

from __future__ import annotations

from os import PathLike

import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from scan2morph.errors import InputError
from scan2morph.io.rgbd import PinholeCamera, RGBDIntrinsics
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
from scan2morph.synth.scanner import backproject, camera_matrix, head_pose, project, render
from scan2morph.synth.texture import texture_seed

#: Sensor parameters of a synthetic RGB-D take, with their defaults.
DEFAULT_RGBD: dict[str, float | int] = {
    "width": 640,  # depth image width, px
    "height": 480,  # depth image height, px
    "focal_px": 600.0,  # depth camera focal length, px
    "color_width": 640,  # colour image width, px
    "color_height": 480,  # colour image height, px
    "color_focal_px": 620.0,  # colour camera focal length, px
    "baseline_mm": 15.0,  # depth to colour camera distance (along x)
    "color_rotation_deg": 0.5,  # colour camera turned about its y axis
    "distance_mm": 600.0,  # depth camera to the front of the face
    "pose_sigma_deg": 2.0,  # random head rotation, per axis
    "pose_sigma_mm": 10.0,  # random head translation, per axis
    "wall_mm": 1500.0,  # depth of the wall behind the head (0: no wall)
    "noise_mm_at_1m": 2.0,  # depth noise (std) at 1 m, growing with z^2
    "depth_unit_mm": 1.0,  # quantisation step = depth_scale_mm of the PNG
    "flying_fraction": 0.5,  # share of depth-edge pixels that become flying pixels
    "edge_jump_mm": 20.0,  # a depth edge: this depth range in a 3 x 3 neighbourhood
    "skin_texture": 1.0,  # strength of the skin's freckles and mottling (0: flat albedo)
    "image_noise": 1.5,  # colour sensor noise, grey levels (std)
    "click_noise_px": 0.5,  # landmark clicking noise on the colour image
    "frames": 1,  # depth frames of the take (the first taken with the colour image)
    "frame_motion_deg": 0.3,  # the head's motion between frames: rotation, per axis (std)
    "frame_motion_mm": 0.5,  # ... and translation, per axis (std)
}
_INT_RGBD = ("width", "height", "color_width", "color_height", "frames")
#: Surfaces that return depth (the mouth cavity and the pupils do not).
_MEASURED = (SEG_SKIN, SEG_BROW, SEG_HAIR, SEG_EYE)


def rgbd_params(params: dict | None = None, source: str = "params") -> dict:
    """:data:`DEFAULT_RGBD` updated with ``params``, checked (names the key on error)."""
    p = numeric_params(params, DEFAULT_RGBD, _INT_RGBD, source)
    for k in ("focal_px", "color_focal_px", "depth_unit_mm"):
        if p[k] <= 0:
            raise InputError(source, f"params.{k}: expected > 0, got {p[k]}")
    for k in ("color_width", "color_height"):
        if not 16 <= p[k] <= 4096:
            raise InputError(source, f"params.{k}: expected 16..4096 pixels, got {p[k]}")
    if p["distance_mm"] < 200.0:
        raise InputError(source, f"params.distance_mm: expected >= 200 mm, got {p['distance_mm']}")
    if p["wall_mm"] and p["wall_mm"] < p["distance_mm"] + 300.0:
        raise InputError(
            source, f"params.wall_mm: expected 0 or >= distance_mm + 300, got {p['wall_mm']}"
        )
    if not 0.0 <= p["flying_fraction"] <= 1.0:
        raise InputError(
            source, f"params.flying_fraction: expected 0..1, got {p['flying_fraction']}"
        )
    for k in ("baseline_mm", "pose_sigma_deg", "pose_sigma_mm", "noise_mm_at_1m", "edge_jump_mm"):
        if p[k] < 0:
            raise InputError(source, f"params.{k}: expected >= 0, got {p[k]}")
    if p["frames"] < 1:
        raise InputError(source, f"params.frames: expected >= 1, got {p['frames']}")
    for k in (
        "image_noise",
        "click_noise_px",
        "skin_texture",
        "frame_motion_deg",
        "frame_motion_mm",
    ):
        if p[k] < 0:
            raise InputError(source, f"params.{k}: expected >= 0, got {p[k]}")
    return p


def sensor(p: dict) -> RGBDIntrinsics:
    """The simulated sensor of checked parameters ``p`` (no lens distortion)."""
    depth = PinholeCamera(
        camera_matrix(p["width"], p["height"], p["focal_px"]),
        np.zeros(5),
        (p["width"], p["height"]),
    )
    size = (p["color_width"], p["color_height"])
    color = PinholeCamera(camera_matrix(*size, p["color_focal_px"]), np.zeros(5), size)
    R = Rotation.from_euler("y", p["color_rotation_deg"], degrees=True).as_matrix()
    T = np.array([-p["baseline_mm"], 0.0, 0.0])
    return RGBDIntrinsics(depth, color, R, T, p["depth_unit_mm"])


def depth_defects(
    depth: np.ndarray, measured: np.ndarray, p: dict, rng: np.random.Generator
) -> np.ndarray:
    """The depth a sensor returns for exact camera Z: wall, flying pixels, noise, quantisation.

    Parameters
    ----------
    depth : (H, W) float
        Exact camera Z, mm; NaN on the background.
    measured : (H, W) bool
        Pixels whose surface returns depth.
    p : dict
        Checked parameters (:func:`rgbd_params`).
    rng : numpy.random.Generator

    Returns
    -------
    (H, W) uint16
        Depth units of ``depth_unit_mm``; 0 = no data.
    """
    background = ~np.isfinite(depth)
    z = np.where(background, p["wall_mm"] or np.nan, depth)
    z[~measured & ~background] = np.nan
    near = ndimage.minimum_filter(np.nan_to_num(z, nan=np.inf), size=3)
    far = ndimage.maximum_filter(np.nan_to_num(z, nan=-np.inf), size=3)
    edge = np.isfinite(z) & np.isfinite(near) & np.isfinite(far) & (far - near > p["edge_jump_mm"])
    flying = edge & (rng.random(z.shape) < p["flying_fraction"])
    t = rng.uniform(0.15, 0.85, size=z.shape)
    z[flying] = near[flying] + t[flying] * (far[flying] - near[flying])
    z = z + p["noise_mm_at_1m"] * (z / 1000.0) ** 2 * rng.standard_normal(z.shape)
    units = np.rint(np.nan_to_num(z, nan=0.0) / p["depth_unit_mm"])
    return np.clip(units, 0, 65535).astype(np.uint16)


def make_rgbd_take(
    subject: str,
    label: str,
    kind: str,
    take: str,
    seed: int,
    params: dict | None = None,
    identity: Identity | None = None,
    convention: str = "synth",
) -> dict:
    """Simulate one RGB-D take of a synthetic subject.

    The face, its articulation and the random part of the head pose are drawn as in
    :func:`~scan2morph.synth.cohort.make_take` (here ``distance_mm`` from the depth camera).

    Parameters
    ----------
    subject, label, kind, take, seed
        As in :func:`~scan2morph.synth.cohort.make_take`.
    params : dict, optional
        Overrides of :data:`DEFAULT_RGBD`.
    identity : Identity, optional
        The face instead of the subject's own (``(seed, subject)``'s); the trainer's.
    convention : str
        Landmark conventions of the truth (``landmarks``, ``landmarks3d``, ``landmarks2d``): one
        of :data:`~scan2morph.synth.convention.CONVENTIONS`, the generator's own by default.
        The ``ibug`` jawline is the colour camera's silhouette.

    Returns
    -------
    dict
        ``depth`` (Hd, Wd) uint16 depth units (with ``frames`` > 1 a list of them, the first
        taken with the colour image, the truth's); ``color`` (Hc, Wc, 3) uint8; ``intrinsics``
        (:class:`~scan2morph.io.rgbd.RGBDIntrinsics`, exact); ``landmarks`` (68, 2) float64
        on the colour image with click noise; ``truth`` (see the module docstring); ids.
    """
    p = rgbd_params(params, check_take(subject, label, kind, take, seed))
    head, vertices, rng = articulated_head(subject, label, kind, take, seed, identity)
    intr = sensor(p)
    pose = head_pose(rng, p["distance_mm"], p["pose_sigma_deg"], p["pose_sigma_mm"], AIM)
    pose_color = intr.color_from_depth @ pose
    _, depth, seg = render(head, vertices, pose, intr.depth.K, *intr.depth.size)
    units = depth_defects(depth, np.isin(seg, _MEASURED), p, rng)
    color, depth_c, seg_c = render(
        head,
        vertices,
        pose_color,
        intr.color.K,
        *intr.color.size,
        p["skin_texture"],
        texture_seed(subject, seed),
    )
    noisy = color.astype(np.float64) + p["image_noise"] * rng.standard_normal(color.shape)
    color = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

    xyz_c = backproject(intr.color.K, depth_c)
    xyz_true = (xyz_c - intr.T) @ intr.R  # colour frame -> depth frame
    lm_index = landmark_vertices(head, vertices, pose_color, convention)
    lm3 = vertices[lm_index] @ pose[:3, :3].T + pose[:3, 3]
    lm2 = project(intr.color.K, lm3 @ intr.R.T + intr.T)
    clicked = lm2 + p["click_noise_px"] * rng.standard_normal(lm2.shape)
    camera = {"K": intr.color.K, "D": intr.color.D}
    truth = _take_truth(
        head,
        vertices,
        pose,
        camera,
        lm3,
        lm2,
        color_from_scanner=intr.color_from_depth,
        xyz_true=xyz_true,
        segment=seg_c,
    )
    depth_out = units
    if p["frames"] > 1:  # drawn last: a one-frame take's draws stay as they were
        poses, frames = _more_frames(head, vertices, pose, intr, p, rng)
        depth_out = [units, *frames]
        truth["frame_poses"] = np.stack([pose, *poses])
    images = {"depth": depth_out, "color": color, "intrinsics": intr}
    return _take_result(images, clicked, truth, subject, take, kind, label)


def _more_frames(head, vertices, pose: np.ndarray, intr: RGBDIntrinsics, p: dict, rng) -> list:
    """Depth frames 2.. of a take: the head turned a little about its origin from ``pose``
    (rotation ``frame_motion_deg``, translation ``frame_motion_mm`` per axis, std), each with
    its own sensor defects. Returns the frames' head -> depth camera poses and their depth
    images."""
    poses, out = [], []
    centre = pose[:3, 3]
    for _ in range(p["frames"] - 1):
        turn = Rotation.from_rotvec(np.deg2rad(p["frame_motion_deg"]) * rng.standard_normal(3))
        motion = np.eye(4)
        motion[:3, :3] = turn.as_matrix()
        motion[:3, 3] = centre - turn.apply(centre) + p["frame_motion_mm"] * rng.standard_normal(3)
        poses.append(motion @ pose)
        _, depth, seg = render(head, vertices, poses[-1], intr.depth.K, *intr.depth.size)
        out.append(depth_defects(depth, np.isin(seg, _MEASURED), p, rng))
    return poses, out


def write_rgbd_take(
    result: dict,
    depth_path: str | PathLike[str],
    color_path: str | PathLike[str],
    intrinsics_path: str | PathLike[str],
    pts_path: str | PathLike[str],
    truth_path: str | PathLike[str],
) -> None:
    """Write a take from :func:`make_rgbd_take` as a user would bring it, plus its truth.

    Parameters
    ----------
    result : dict
        Output of :func:`make_rgbd_take`.
    depth_path : str or path-like, or a list of them
        16-bit depth PNG (units of ``depth_scale_mm``); one per frame for a take of several.
    color_path : str or path-like
        Colour image (PNG).
    intrinsics_path : str or path-like
        The sensor's intrinsics YAML (:func:`~scan2morph.io.rgbd.write_rgbd_intrinsics`).
    pts_path : str or path-like
        iBUG 68-point ``.pts`` on the colour image (1-based).
    truth_path : str or path-like
        ``.npz``: the keys of a range take's truth plus ``D``, ``color_from_scanner``,
        ``xyz_true`` and ``segment`` (module docstring).
    """
    from scan2morph.io import write_color, write_pts
    from scan2morph.io.depth_image import write_depth_png
    from scan2morph.io.rgbd import write_rgbd_intrinsics

    keys = ("depth", "color", "intrinsics", "landmarks", "truth")
    _check_result(result, keys, str(truth_path), "make_rgbd_take")
    frames = result["depth"] if isinstance(result["depth"], list) else [result["depth"]]
    paths = depth_path if isinstance(depth_path, list | tuple) else [depth_path]
    if len(paths) != len(frames):
        raise InputError(str(truth_path), f"{len(frames)} depth frames but {len(paths)} paths")
    for path, frame in zip(paths, frames, strict=True):
        write_depth_png(path, frame)
    write_color(color_path, result["color"])
    write_rgbd_intrinsics(intrinsics_path, result["intrinsics"])
    write_pts(pts_path, result["landmarks"])
    write_npz(truth_path, result["truth"])


__all__ = ["DEFAULT_RGBD", "depth_defects", "make_rgbd_take", "rgbd_params", "write_rgbd_take"]
