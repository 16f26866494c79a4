"""A simulated calibrated stereo rig: two distorted pinhole cameras and a speckled face.

The rig (mm; rig frame: x right, y down, z forward, origin midway between the cameras) holds
two cameras ``baseline_mm`` apart, each turned ``toe_in_deg`` towards the other, with mild
radial lens distortion (OpenCV's model, ``k1``) and the small imperfections of a real rig
(slightly different focal lengths and principal points, a small tilt of the right camera).
The head sits ``distance_mm`` in front of the rig, with the same random pose as a range take.

Images are rendered with pyrender (OSMesa) as undistorted pinhole views at ``supersample``
times the resolution, then resampled with :func:`cv2.remap` at ``supersample``^2 sub-pixel
positions of the distorted image per pixel and box-averaged, so that the written images are
distorted exactly as the calibration says. Lights are fixed in the rig (a lamp midway between
the cameras and a key light from the upper left: :func:`~scan2morph.synth.scanner.shade` in
the rig frame), so both cameras see the same shading. The skin's albedo is blended with a
random speckle (the random texture the stereo paper sprays on the face for correlation):
solid value noise over the skin's rest positions (the paint moves with the skin) with cells of
``speckle_px`` pixels at the head's distance, fixed per subject, and with the skin's own detail
(:mod:`~scan2morph.synth.texture`), both applied per rendered pixel (the mesh's ~1.3 mm vertex
spacing is too coarse to carry them per vertex).

The ground truth of every left pixel is the exact hit of its (undistorted) ray with the head
mesh, ray cast with Open3D, independently of the renderer.

Pixel convention: (0, 0) is the centre of the top-left pixel (OpenCV's, for
:func:`cv2.projectPoints` and :func:`cv2.undistortPoints` alike).
"""

from __future__ import annotations

import os
from os import PathLike

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from scan2morph.errors import InputError  # noqa: E402
from scan2morph.geometry import vertex_normals  # noqa: E402
from scan2morph.io.calibration import StereoCalibration  # noqa: E402
from scan2morph.jobs import write_npz
from scan2morph.open3d_light import open3d, triangle_scene  # noqa: E402
from scan2morph.synth.cohort import (  # noqa: E402
    AIM,
    _check_result,
    _take_result,
    _take_truth,
    articulated_head,
    check_take,
    numeric_params,
    text_seed,
)
from scan2morph.synth.convention import landmark_vertices  # noqa: E402
from scan2morph.synth.head import SEG_SKIN, HeadModel, Identity  # noqa: E402
from scan2morph.synth.scanner import (  # noqa: E402
    BACKGROUND_RGB,
    head_pose,
    render_colors,
    shade,
)
from scan2morph.synth.texture import (  # noqa: E402
    rest_positions,
    skin_detail,
    texture_seed,
    value_noise,
)

#: Rig and image parameters of a synthetic stereo take, with their defaults.
DEFAULT_RIG: dict[str, float | int] = {
    "width": 640,  # image width, px
    "height": 480,  # image height, px
    "focal_px": 1300.0,  # focal length of the left camera, px (the right one's is 0.4% longer)
    "distance_mm": 650.0,  # rig centre to the front of the face
    "baseline_mm": 120.0,  # distance between the camera centres
    "toe_in_deg": 4.0,  # each camera turned inwards by this angle
    "k1": -0.05,  # radial distortion of the left camera (the right one's is 0.9 k1)
    "pose_sigma_deg": 2.0,  # random head rotation, per axis
    "pose_sigma_mm": 10.0,  # random head translation, per axis
    "speckle_px": 2.5,  # speckle cell size in pixels at distance_mm
    "speckle_contrast": 0.5,  # darkest speckle multiplies the skin albedo by 1 - contrast
    "image_noise": 1.5,  # sensor noise, grey levels (std)
    "click_noise_px": 0.5,  # landmark clicking noise
    "supersample": 3,  # rendered sub-pixels per pixel and axis (odd: one sits on the centre)
    "skin_texture": 1.0,  # strength of the skin's freckles and mottling (0: flat albedo)
}

_INT_RIG = ("width", "height", "supersample")
#: Remap tables per camera (intrinsics, distortion, size, supersampling): one rig per job.
_TABLES: dict[bytes, tuple] = {}


def rig_params(params: dict | None = None, source: str = "params") -> dict:
    """:data:`DEFAULT_RIG` updated with ``params``, checked.

    Parameters
    ----------
    params : dict, optional
        Overrides of :data:`DEFAULT_RIG`.
    source : str
        Named in the errors (``subject/take``).

    Returns
    -------
    dict
        Every key of :data:`DEFAULT_RIG`.

    Raises
    ------
    InputError
        An unknown key or a value out of range (names the key).
    """
    p = numeric_params(params, DEFAULT_RIG, _INT_RIG, source)
    for k in ("focal_px", "baseline_mm", "speckle_px"):
        if p[k] <= 0:
            raise InputError(source, f"params.{k}: expected > 0, got {p[k]}")
    if p["distance_mm"] < 300.0:
        raise InputError(source, f"params.distance_mm: expected >= 300 mm, got {p['distance_mm']}")
    if not 0.0 <= p["toe_in_deg"] <= 20.0:
        raise InputError(
            source, f"params.toe_in_deg: expected 0..20 degrees, got {p['toe_in_deg']}"
        )
    if not -0.5 <= p["k1"] <= 0.5:
        raise InputError(source, f"params.k1: expected -0.5..0.5 (mild distortion), got {p['k1']}")
    if not 0.0 <= p["speckle_contrast"] <= 1.0:
        raise InputError(
            source, f"params.speckle_contrast: expected 0..1, got {p['speckle_contrast']}"
        )
    for k in ("pose_sigma_deg", "pose_sigma_mm", "image_noise", "click_noise_px", "skin_texture"):
        if p[k] < 0:
            raise InputError(source, f"params.{k}: expected >= 0, got {p[k]}")
    if not (1 <= p["supersample"] <= 7 and p["supersample"] % 2 == 1):
        raise InputError(
            source, f"params.supersample: expected an odd number 1..7, got {p['supersample']}"
        )
    return p


def _rot(axis: int, angle: float) -> np.ndarray:
    """Rotation by ``angle`` rad about the coordinate axis ``axis`` (0 x, 1 y), (3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    if axis == 0:
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rig_cameras(params: dict | None = None) -> tuple[list[dict], StereoCalibration]:
    """Both cameras of the rig and their exact calibration.

    Parameters
    ----------
    params : dict, optional
        Overrides of :data:`DEFAULT_RIG`.

    Returns
    -------
    cams : list of two dict
        Left then right camera: ``K`` (3, 3) px, ``D`` (5,) OpenCV distortion
        ``(k1, k2, p1, p2, k3)``, ``R`` (3, 3) camera -> rig rotation, ``C`` (3,) centre in
        the rig frame, mm. A rig point ``p`` is ``R.T @ (p - C)`` in the camera frame.
    calib : StereoCalibration
        ``x_right = R @ x_left + T`` (mm), with ``image_size = (width, height)``.
    """
    p = rig_params(params)
    w, h, f = p["width"], p["height"], p["focal_px"]
    s = w / 640.0  # principal point offsets scale with the image
    toe = np.deg2rad(p["toe_in_deg"])
    half = 0.5 * p["baseline_mm"]
    cams = [
        {
            "K": np.array(
                [[f, 0.0, 0.5 * (w - 1) + 3.0 * s], [0.0, f, 0.5 * (h - 1) - 2.0 * s], [0, 0, 1]]
            ),
            "D": np.array([p["k1"], 0.0, 0.0, 0.0, 0.0]),
            "R": _rot(1, toe),
            "C": np.array([-half, 0.0, 0.0]),
        },
        {
            "K": np.array(
                [
                    [1.004 * f, 0.0, 0.5 * (w - 1) - 4.0 * s],
                    [0.0, 1.004 * f, 0.5 * (h - 1) + 1.5 * s],
                    [0, 0, 1],
                ]
            ),
            "D": np.array([0.9 * p["k1"], 0.0, 0.0, 0.0, 0.0]),
            "R": _rot(1, -toe) @ _rot(0, np.deg2rad(0.2)),
            "C": np.array([half, 0.5, -1.0]),
        },
    ]
    left, right = cams
    R = right["R"].T @ left["R"]
    T = right["R"].T @ (left["C"] - right["C"])
    calib = StereoCalibration(left["K"], left["D"], right["K"], right["D"], R, T, (w, h))
    return cams, calib


def speckle(points: np.ndarray, cell_mm: float, seed: int) -> np.ndarray:
    """Random speckle intensity of head-frame points: 3D value noise, contrast-stretched.

    Random values on a cubic lattice of spacing ``cell_mm`` (a hash of the integer lattice
    coordinates and ``seed``), interpolated trilinearly, then stretched about 0.5 and clipped
    to [0, 1] so that the pattern has dark and bright speckles of about one cell.

    Parameters
    ----------
    points : (n, 3) float
        Head frame, mm.
    cell_mm : float
        Lattice spacing, mm (the speckle's feature size).
    seed : int
        Fixes the pattern (0 <= seed < 2**64).

    Returns
    -------
    (n,) float64
        In [0, 1]; 1 = darkest speckle.
    """
    value = value_noise(points, cell_mm, seed)
    # trilinear interpolation of uniform values spreads less (std ~0.12): stretch to speckle
    return np.clip(0.5 + (value - 0.5) / 0.3, 0.0, 1.0)


def _remap_tables(K: np.ndarray, D: np.ndarray, width: int, height: int, s: int):
    """Where the distorted image's sub-pixels fall in an undistorted pinhole render.

    Returns the render's intrinsics ``K_u`` (focal lengths ``s`` times ``K``'s), its size
    ``(w_u, h_u)`` covering every sub-pixel with a margin, the remap tables
    ``(map_x, map_y)`` of shape (height s, width s), float32, render pixel coordinates, and the
    undistorted normalised coordinates (height width, 2) float64 of the pixel centres (the
    middle sub-pixels: ``s`` is odd), rows first.
    """
    key = np.concatenate([K.ravel(), D.ravel(), [width, height, s]]).tobytes()
    if key in _TABLES:
        return _TABLES[key]
    sub = (np.arange(s) + 0.5) / s - 0.5  # sub-pixel offsets; the middle one is the centre
    xs = (np.arange(width)[:, None] + sub[None, :]).ravel()
    ys = (np.arange(height)[:, None] + sub[None, :]).ravel()
    X, Y = np.meshgrid(xs, ys)
    pix = np.stack([X.ravel(), Y.ravel()], axis=-1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-12)
    norm = cv2.undistortPoints(pix, K, D, criteria=criteria).reshape(-1, 2)
    fx, fy = s * K[0, 0], s * K[1, 1]
    margin = 4.0
    lo, hi = norm.min(axis=0), norm.max(axis=0)
    K_u = np.array(
        [[fx, 0.0, margin - lo[0] * fx], [0.0, fy, margin - lo[1] * fy], [0.0, 0.0, 1.0]]
    )
    size = (
        int(np.ceil((hi[0] - lo[0]) * fx + 2 * margin)) + 1,
        int(np.ceil((hi[1] - lo[1]) * fy + 2 * margin)) + 1,
    )
    map_x = (norm[:, 0] * fx + K_u[0, 2]).astype(np.float32).reshape(len(ys), len(xs))
    map_y = (norm[:, 1] * fy + K_u[1, 2]).astype(np.float32).reshape(len(ys), len(xs))
    centres = norm.reshape(height, s, width, s, 2)[:, s // 2, :, s // 2].reshape(-1, 2).copy()
    if len(_TABLES) >= 4:  # one rig per job: a few cameras' tables are all we need
        _TABLES.pop(next(iter(_TABLES)))
    _TABLES[key] = (K_u, size, map_x, map_y, centres)
    return _TABLES[key]


def _view(
    head: HeadModel,
    v_rig: np.ndarray,
    colors: np.ndarray,
    cam: dict,
    p: dict,
    seeds: tuple[int, int],
    rng: np.random.Generator,
) -> np.ndarray:
    """The raw (distorted) image of one camera, (height, width, 3) uint8.

    ``seeds`` are the speckle's and the skin detail's."""
    s = int(p["supersample"])
    K_u, size, map_x, map_y, _ = _remap_tables(cam["K"], cam["D"], p["width"], p["height"], s)
    v_cam = (v_rig - cam["C"]) @ cam["R"]
    color, depth, seg = render_colors(head, v_cam, colors, K_u, size)
    image = color.astype(np.float32)
    skin = seg == SEG_SKIN
    if skin.any():
        # the rest position of the skin point each render pixel sees: the speckle (sprayed
        # paint) and the skin detail are fixed to the skin and move with it
        rows, cols = np.nonzero(skin)
        rays = np.column_stack([cols, rows, np.ones(len(rows))]) @ np.linalg.inv(K_u).T
        rest = rest_positions(v_cam, head.faces, head.vertices, rays)
        hit = np.isfinite(rest).all(axis=1)
        factor = np.ones((len(rows), 3))
        factor[hit] = skin_detail(rest[hit], seeds[1], p["skin_texture"])
        if p["speckle_contrast"] > 0:
            cell_mm = p["speckle_px"] * p["distance_mm"] / p["focal_px"]
            dots = speckle(np.where(hit[:, None], rest, 0.0), cell_mm, seeds[0])
            factor *= np.where(hit, 1.0 - p["speckle_contrast"] * dots, 1.0)[:, None]
        image[rows, cols] *= factor.astype(np.float32)
    sampled = cv2.remap(
        image,
        map_x,
        map_y,
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=tuple(float(c) for c in BACKGROUND_RGB),
    )
    # the mean of each pixel's s x s sub-pixels (INTER_AREA is exactly that for integer s)
    pixel = cv2.resize(sampled, (p["width"], p["height"]), interpolation=cv2.INTER_AREA)
    pixel = pixel.astype(np.float64) + p["image_noise"] * rng.standard_normal(pixel.shape)
    return np.clip(np.rint(pixel), 0, 255).astype(np.uint8)


def _left_truth(
    head: HeadModel, v_left: np.ndarray, cam: dict, p: dict
) -> tuple[np.ndarray, np.ndarray]:
    """Exact surface point and segment of every left pixel centre (ray cast with Open3D).

    The centres' undistorted rays are those of the left view's remap tables (its middle
    sub-pixels, the same :func:`cv2.undistortPoints` of the same points)."""
    o3d = open3d()

    width, height = p["width"], p["height"]
    norm = _remap_tables(cam["K"], cam["D"], width, height, int(p["supersample"]))[4]
    dirs = np.concatenate([norm, np.ones((len(norm), 1))], axis=1)  # ray (x, y, 1): t = Z
    scene = triangle_scene(v_left, head.faces)
    rays = np.concatenate([np.zeros_like(dirs), dirs], axis=1).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))
    z = hit["t_hit"].numpy().astype(np.float64)
    prim = hit["primitive_ids"].numpy().astype(np.int64)
    found = np.isfinite(z)
    segment = np.full(len(z), -1, dtype=np.int8)
    segment[found] = head.segment[prim[found]]
    xyz = np.where(found[:, None], dirs * np.where(found, z, 0.0)[:, None], np.nan)
    return xyz.reshape(height, width, 3), segment.reshape(height, width)


def make_stereo_take(
    subject: str,
    label: str,
    kind: str,
    take: str,
    seed: int,
    params: dict | None = None,
    identity: Identity | None = None,
    convention: str = "synth",
) -> dict:
    """Simulate one stereo take of a synthetic subject.

    The face, its articulation and the random part of the head pose are drawn as in
    :func:`~scan2morph.synth.cohort.make_take` (the same ``(seed, subject, take)`` gives the
    same face, here ``distance_mm`` in front of the rig).

    Parameters
    ----------
    subject, label, kind, take, seed
        As in :func:`~scan2morph.synth.cohort.make_take`.
    params : dict, optional
        Overrides of :data:`DEFAULT_RIG`.
    identity : Identity, optional
        The face instead of the subject's own (``(seed, subject)``'s); the trainer's.
    convention : str
        Landmark conventions of the truth (``landmarks``, ``landmarks3d``, ``landmarks2d``): one
        of :data:`~scan2morph.synth.convention.CONVENTIONS`, the generator's own by default.

    Returns
    -------
    dict
        ``left``, ``right`` (H, W, 3) uint8 raw (distorted) RGB images; ``calib``
        (:class:`~scan2morph.io.StereoCalibration`, exact); ``landmarks`` (68, 2) float64
        pixel coordinates on the raw left image, with click noise; ``truth`` (dict of arrays,
        see :func:`write_stereo_take`); ``subject``, ``take``, ``kind``, ``label``.

    Raises
    ------
    InputError
        On an unknown label, a kind that does not match it, a bad id or seed, or bad params.
    """
    p = rig_params(params, check_take(subject, label, kind, take, seed))
    head, vertices, rng = articulated_head(subject, label, kind, take, seed, identity)
    rig_from_head = head_pose(rng, p["distance_mm"], p["pose_sigma_deg"], p["pose_sigma_mm"], AIM)
    cams, calib = rig_cameras(p)
    v_rig = vertices @ rig_from_head[:3, :3].T + rig_from_head[:3, 3]
    # lights fixed in the rig: both cameras see the same shading
    colors = shade(head.albedo, v_rig, vertex_normals(v_rig, head.faces, fill=0.0))
    seeds = ((text_seed(subject) ^ int(seed)) & 0xFFFFFFFFFFFFFFFF, texture_seed(subject, seed))
    left, right = (_view(head, v_rig, colors, cam, p, seeds, rng) for cam in cams)

    cam1 = cams[0]
    left_from_rig = np.eye(4)
    left_from_rig[:3, :3] = cam1["R"].T
    left_from_rig[:3, 3] = -cam1["R"].T @ cam1["C"]
    pose = left_from_rig @ rig_from_head
    v_left = vertices @ pose[:3, :3].T + pose[:3, 3]
    xyz_true, segment = _left_truth(head, v_left, cam1, p)
    lm3 = v_left[landmark_vertices(head, vertices, pose, convention)]
    lm2 = cv2.projectPoints(lm3, np.zeros(3), np.zeros(3), cam1["K"], cam1["D"])[0].reshape(-1, 2)
    clicked = lm2 + p["click_noise_px"] * rng.standard_normal(lm2.shape)
    camera = {"K": cam1["K"], "D": cam1["D"]}
    truth = _take_truth(head, vertices, pose, camera, lm3, lm2, xyz_true=xyz_true, segment=segment)
    images = {"left": left, "right": right, "calib": calib}
    return _take_result(images, clicked, truth, subject, take, kind, label)


def write_stereo_take(
    result: dict,
    left_path: str | PathLike[str],
    right_path: str | PathLike[str],
    calibration_path: str | PathLike[str],
    pts_path: str | PathLike[str],
    truth_path: str | PathLike[str],
) -> None:
    """Write a take from :func:`make_stereo_take` as a user would bring it, plus its truth.

    Parameters
    ----------
    result : dict
        Output of :func:`make_stereo_take`.
    left_path, right_path : str or path-like
        The raw images (PNG).
    calibration_path : str or path-like
        OpenCV FileStorage YAML (``%YAML:1.0``; ``K1 D1 K2 D2 R T``, mm; image size).
    pts_path : str or path-like
        iBUG 68-point ``.pts`` on the raw left image (1-based).
    truth_path : str or path-like
        ``.npz`` with the keys of a range take's truth (see
        :func:`~scan2morph.synth.cohort.write_take`; ``pose`` maps the head into the left
        camera frame, ``K`` is the left camera's, ``landmarks2d`` are exact projections on the
        raw left image) plus ``D`` (5,) the left camera's distortion, ``xyz_true``
        (H, W, 3) float64 the exact surface point of every left pixel centre in the left
        camera frame, mm, NaN where the ray meets no surface, and ``segment`` (H, W) int8 the
        ``SEG_*`` code of that surface (:data:`~scan2morph.synth.head.SEG_SKIN` = 0 is skin),
        -1 where there is none.
    """
    from scan2morph.io import write_color, write_pts, write_stereo_calibration

    keys = ("left", "right", "calib", "landmarks", "truth")
    _check_result(result, keys, str(truth_path), "make_stereo_take")
    write_color(left_path, result["left"])
    write_color(right_path, result["right"])
    write_stereo_calibration(calibration_path, result["calib"])
    write_pts(pts_path, result["landmarks"])
    write_npz(truth_path, result["truth"])


__all__ = [
    "DEFAULT_RIG",
    "make_stereo_take",
    "rig_cameras",
    "rig_params",
    "speckle",
    "write_stereo_take",
]
