"""RGB-D takes: a depth image, its intrinsics YAML and a colour image -> XYZ on the colour grid.

Intrinsics file (plain YAML, OpenCV's pinhole convention: (0, 0) is the centre of the top-left
pixel; distances in mm)::

    width: 640            # depth image, px
    height: 480
    fx: 385.0             # depth camera, px
    fy: 385.0
    cx: 319.5
    cy: 239.5
    depth_scale_mm: 1.0   # mm per depth unit (RealSense: 1.0; 0.1 for 100 um units); 0 = no data
    distortion: [k1, k2, p1, p2, k3]   # optional (OpenCV order), or a mapping k1: ... k3:
    color:                # optional: the colour camera, when it is not the depth camera
      width: 640
      height: 480
      fx: 610.0
      fy: 610.0
      cx: 319.5
      cy: 239.5
      R: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]   # depth -> colour rotation
      T: [15.0, 0.0, 0.0]                    # depth -> colour translation, mm
      distortion: [k1, k2, p1, p2, k3]       # optional

``x_color = R @ x_depth + T``. Without a ``color`` block the colour image is taken with the
depth camera itself (same size, pixel to pixel).

Several depth frames. A take's ``depth`` may name several frames of the same pose: files
separated by ``;``, or a folder (its ``.png``/``.npy``/``.npz`` files in name order). The first
frame is the one the colour image was taken with. :func:`read_rgbd_take` hands the frames (in
mm) to a ``fuse`` function (:func:`scan2morph.scan.fusion.fuse_depth_frames`, which registers
and averages them) and goes on with the fused depth.

The take's range image lies on the **colour** image's pixel grid (where the landmarks are
clicked) and its XYZ in the **depth camera's** frame (mm, OpenCV axes). Every colour pixel's
point is where its ray meets the depth surface: the depth image is triangulated (two triangles
per 2 x 2 block of pixels with data, none across a depth step) and each triangle is rasterised
into the colour camera exactly (inside test and perspective-correct depth in undistorted
normalised coordinates), nearest surface first. Colour pixels the depth camera did not see (the
shadow of the baseline beside the nose, beyond the silhouette) get no data; repair fills the
small holes and removes flying pixels.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.calibration import MIN_BASELINE_MM
from scan2morph.io.depth_image import check_face_depth, depth_frame_paths, read_depth_frames
from scan2morph.io.image import read_color
from scan2morph.io.landmarks import complete, read_pts
from scan2morph.io.take import RangeTake, check_face, check_image_size, check_landmarks_inside
from scan2morph.io.text_file import utf8_text
from scan2morph.io.yaml_text import load_yaml, yaml_problem

#: A triangle of neighbouring depth pixels steeper than this to the view ray spans a depth step
#: and is not meshed, degrees (a face's steepest measured parts, nose sides, are ~75).
EDGE_SLOPE_DEG = 80.0
#: Largest side of a triangle's box on the colour image, px (a colour camera with up to ~6x the
#: depth camera's resolution); larger triangles are depth steps seen obliquely and are skipped.
MAX_TRIANGLE_PX = 8
#: Largest ``max|R^T R - I|`` accepted for the depth -> colour rotation.
ROTATION_TOL = 1e-4
#: Widest field of view accepted for a camera, degrees (wide-angle depth sensors: ~120): a
#: smaller focal length in px is one given normalised (divided by the image size) or in mm.
MAX_FOV_DEG = 150.0
#: A principal point within this share of the width (height) of (0, 0) is one given as an
#: offset from the image's centre (or left at a default): a lens's axis crosses its image well
#: inside it. Anywhere else is accepted: an image cropped to the face may put it off-centre.
PRINCIPAL_POINT_AT_ORIGIN = 0.05
_DISTORTION = ("k1", "k2", "p1", "p2", "k3")
_PINHOLE = ("width", "height", "fx", "fy", "cx", "cy")


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """One camera of an RGB-D sensor.

    Attributes
    ----------
    K : (3, 3) float64
        Intrinsics, px.
    D : (5,) float64
        OpenCV distortion ``k1 k2 p1 p2 k3`` (zeros: none).
    size : (int, int)
        Image ``(width, height)``, px.
    """

    K: np.ndarray
    D: np.ndarray
    size: tuple[int, int]


@dataclass(frozen=True, eq=False)
class RGBDIntrinsics:
    """An RGB-D sensor: depth camera, colour camera and the rigid motion between them.

    Attributes
    ----------
    depth, color : PinholeCamera
        ``color`` is ``depth`` when the file has no ``color`` block.
    R : (3, 3) float64
        Depth -> colour rotation.
    T : (3,) float64
        Depth -> colour translation, mm (``x_color = R @ x_depth + T``).
    depth_scale_mm : float
        mm per depth unit.
    """

    depth: PinholeCamera
    color: PinholeCamera
    R: np.ndarray
    T: np.ndarray
    depth_scale_mm: float

    @property
    def color_from_depth(self) -> np.ndarray:
        """(4, 4) float64 depth camera frame -> colour camera frame, mm."""
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = self.R, self.T
        return out


def _number(block: dict, key: str, source, where: str, positive: bool = False) -> float:
    if key not in block:
        raise InputError(source, f"{where}{key}: missing (expected a number)")
    value = block[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(source, f"{where}{key}: expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise InputError(source, f"{where}{key}: expected > 0, got {value!r}")
    return float(value)


def _matrix(value, shape: tuple[int, ...], source, field: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(source, f"{field}: expected {shape} numbers, got {value!r}") from None
    if arr.size != int(np.prod(shape)) or not np.isfinite(arr).all():
        raise InputError(source, f"{field}: expected {shape} finite numbers, got {value!r}")
    return arr.reshape(shape)


def _distortion(value, source, field: str) -> np.ndarray:
    if value is None:
        return np.zeros(5)
    if isinstance(value, dict):
        unknown = sorted(set(value) - set(_DISTORTION))
        if unknown:
            raise InputError(source, f"{field}: unknown keys {unknown} (expected {_DISTORTION})")
        value = [value.get(k, 0.0) for k in _DISTORTION]
    return _matrix(value, (5,), source, f"{field} (OpenCV k1 k2 p1 p2 k3)")


def _camera(block, source, where: str) -> PinholeCamera:
    if not isinstance(block, dict):
        raise InputError(source, f"{where.rstrip('.') or 'file'}: expected a mapping")
    vals = {k: _number(block, k, source, where, positive=k in _PINHOLE[:4]) for k in _PINHOLE}
    for k in ("width", "height"):
        if vals[k] != int(vals[k]):
            raise InputError(source, f"{where}{k}: expected an integer, got {block[k]!r}")
    _check_pinhole(vals, source, where)
    K = np.array([[vals["fx"], 0, vals["cx"]], [0, vals["fy"], vals["cy"]], [0, 0, 1.0]])
    D = _distortion(block.get("distortion"), source, f"{where}distortion")
    return PinholeCamera(K, D, (int(vals["width"]), int(vals["height"])))


def _check_pinhole(vals: dict, source, where: str) -> None:
    """Refuse a focal length wider than :data:`MAX_FOV_DEG` (intrinsics normalised or in mm) or
    a principal point near (0, 0) (:data:`PRINCIPAL_POINT_AT_ORIGIN`)."""
    for f, side in (("fx", "width"), ("fy", "height")):
        fov = 2.0 * np.degrees(np.arctan(vals[side] / 2.0 / vals[f]))
        if fov > MAX_FOV_DEG:
            raise InputError(
                source,
                f"{where}{f}: {vals[f]:g} px for a {side} of {vals[side]:g} px is a {fov:.0f}° "
                f"field of view (at most {MAX_FOV_DEG:g}° expected): are the intrinsics "
                "normalised (divided by the image size) or in mm? expected px",
            )
    w, h, cx, cy = (vals[k] for k in ("width", "height", "cx", "cy"))
    m = PRINCIPAL_POINT_AT_ORIGIN
    if abs(cx) < m * w and abs(cy) < m * h:
        raise InputError(
            source,
            f"{where}cx/{where}cy: the principal point ({cx:g}, {cy:g}) px lies at the image's corner, "
            f"not near the centre of the {w:g}x{h:g} image ({(w - 1) / 2:g}, {(h - 1) / 2:g}): is "
            "it given as an offset from the centre? expected px, with (0, 0) at the centre of "
            "the top-left pixel",
        )


def _known_keys(block: dict, known: tuple[str, ...], source, where: str) -> None:
    """Refuse a key the format does not have (a misspelt ``distorsion`` was ignored: the take
    was resampled without its distortion)."""
    if unknown := [k for k in block if k not in known]:
        raise InputError(source, f"{where}{unknown[0]}: unknown key (known: {', '.join(known)})")


def read_rgbd_intrinsics(path: str | Path) -> RGBDIntrinsics:
    """Read an RGB-D intrinsics YAML (see the module docstring).

    Raises
    ------
    InputError
        Missing file, not YAML, a key given twice, a key missing or not a number, an unknown
        key, a non-positive focal length or size, a focal length of a field of view wider than
        :data:`MAX_FOV_DEG` or a principal point near the image's side (normalised
        intrinsics), ``depth_scale_mm`` <= 0, ``R`` not a rotation, ``T`` not 3 numbers or
        under 1 mm but not 0 (in metres) (names the key).
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected an RGB-D intrinsics YAML)")
    text = utf8_text(path)
    try:
        doc = load_yaml(text)
    except yaml.YAMLError as exc:
        raise InputError(path, f"cannot read as YAML: {yaml_problem(exc)}") from None
    if not isinstance(doc, dict):
        raise InputError(path, f"expected a mapping with keys {list(_PINHOLE)}, got {doc!r:.60}")
    _known_keys(doc, (*_PINHOLE, "depth_scale_mm", "distortion", "color"), path, "")
    depth = _camera(doc, path, "")
    scale = _number(doc, "depth_scale_mm", path, "", positive=True)
    color, R, T = depth, np.eye(3), np.zeros(3)
    if doc.get("color") is not None:
        block = doc["color"]
        color = _camera(block, path, "color.")
        _known_keys(block, (*_PINHOLE, "distortion", "R", "T"), path, "color.")
        R = _matrix(block.get("R", np.eye(3).tolist()), (3, 3), path, "color.R")
        if "T" not in block:  # a zero baseline read for a missing one puts the colour mm off
            raise InputError(
                path,
                "color.T: missing (the depth -> colour translation, mm, e.g. [15.0, 0.0, 0.0]; "
                "[0, 0, 0] when the colour camera sits at the depth camera's centre)",
            )
        T = _matrix(block["T"], (3,), path, "color.T (mm)")
        baseline = float(np.linalg.norm(T))
        if 0.0 < baseline < MIN_BASELINE_MM:  # 0: the colour image is the depth camera's
            raise InputError(
                path,
                f"color.T: |T| = {baseline:.6g} is below {MIN_BASELINE_MM:g} mm; T must be in mm "
                "(is it in metres?), or 0 when the colour camera is the depth camera",
            )
        if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOL or np.linalg.det(R) < 0:
            raise InputError(path, "color.R: not a rotation matrix (R^T R != I or det < 0)")
    return RGBDIntrinsics(depth, color, R, T, scale)


def _rays(camera: PinholeCamera) -> np.ndarray:
    """(H, W, 2) undistorted normalised coordinates ``(x / z, y / z)`` of every pixel centre."""
    w, h = camera.size
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    pix = np.stack([u, v], axis=-1).reshape(-1, 1, 2)
    if not camera.D.any():
        K = camera.K
        return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]], axis=-1)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
    norm = cv2.undistortPoints(pix, camera.K, camera.D, criteria=criteria)
    return norm.reshape(h, w, 2)


def _to_pixels(camera: PinholeCamera, norm: np.ndarray) -> np.ndarray:
    """Pixel coordinates (n, 2) of undistorted normalised coordinates (n, 2)."""
    pts = np.column_stack([norm, np.ones(len(norm))])
    return cv2.projectPoints(pts, np.zeros(3), np.zeros(3), camera.K, camera.D)[0].reshape(-1, 2)


def project_points(camera: PinholeCamera, xyz: np.ndarray) -> np.ndarray:
    """Pixel coordinates (n, 2) of points (n, 3) in the camera's frame (mm, z > 0), with the
    camera's distortion."""
    xyz = np.asarray(xyz, dtype=np.float64)
    return _to_pixels(camera, xyz[:, :2] / xyz[:, 2:3])


def depth_points(depth_mm: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    """XYZ (H, W, 3) of every depth pixel in the depth camera's frame, mm; NaN without data."""
    z = np.where(depth_mm > 0, depth_mm, np.nan)
    rays = _rays(camera)
    return np.concatenate([rays * z[..., None], z[..., None]], axis=-1)


def _triangles(z: np.ndarray, focal_px: float) -> np.ndarray:
    """(T, 3) flat pixel indices of the triangles of a depth grid (two per 2 x 2 block whose
    corners have data), leaving out triangles steeper than :data:`EDGE_SLOPE_DEG`."""
    h, w = z.shape
    idx = np.arange(h * w).reshape(h, w)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    tris = np.concatenate([np.stack([a, b, c], -1), np.stack([b, d, c], -1)]).reshape(-1, 3)
    z = z.reshape(-1)
    # the corners' depths one column at a time: the same sums, minima and maxima as numpy's
    # reductions over the corner axis of (T, 3), which cost 0.1 s on a 640 x 480 grid
    ok = np.isfinite(z)
    tris = tris[ok[tris[:, 0]] & ok[tris[:, 1]] & ok[tris[:, 2]]]
    z0, z1, z2 = z[tris[:, 0]], z[tris[:, 1]], z[tris[:, 2]]
    # depth change across one pixel pitch (z / f) of a surface at EDGE_SLOPE_DEG to the ray
    limit = np.tan(np.deg2rad(EDGE_SLOPE_DEG)) * ((z0 + z1 + z2) / 3) / focal_px
    ptp = np.maximum(np.maximum(z0, z1), z2) - np.minimum(np.minimum(z0, z1), z2)
    return tris[ptp <= limit]


def depth_to_color_grid(depth_mm: np.ndarray, intr: RGBDIntrinsics) -> np.ndarray:
    """XYZ of every colour pixel (the depth surface on its ray), in the depth camera's frame.

    Parameters
    ----------
    depth_mm : (Hd, Wd) float
        Depth (camera Z) in mm; 0 or NaN = no data.
    intr : RGBDIntrinsics

    Returns
    -------
    (Hc, Wc, 3) float64
        mm, NaN where the colour pixel's ray meets no meshed depth surface.
    """
    pts = depth_points(depth_mm, intr.depth)
    if intr.color is intr.depth:
        return pts
    xyz_c = surface_on_camera(pts, float(intr.depth.K[0, 0]), intr.color, intr.color_from_depth)
    return ((xyz_c.reshape(-1, 3) - intr.T) @ intr.R).reshape(xyz_c.shape)


def surface_on_camera(
    pts: np.ndarray, focal_px: float, camera: PinholeCamera, pose: np.ndarray
) -> np.ndarray:
    """Where every pixel's ray of ``camera`` meets a depth grid's triangulated surface.

    The grid is triangulated (two triangles per 2 x 2 block of pixels with data, none across a
    depth step) and each triangle rasterised into ``camera`` exactly (inside test and
    perspective-correct depth in undistorted normalised coordinates), nearest surface first.

    Parameters
    ----------
    pts : (H, W, 3) float
        The depth grid's points in its own camera's frame, mm; NaN without data.
    focal_px : float
        The depth grid's focal length, px (sets the steepest triangle meshed).
    camera : PinholeCamera
        The camera whose pixels are filled.
    pose : (4, 4) float
        Depth grid's frame -> ``camera``'s frame, mm.

    Returns
    -------
    (Hc, Wc, 3) float64
        mm in ``camera``'s frame, NaN where a pixel's ray meets no triangle.
    """
    wc, hc = camera.size
    R, T = pose[:3, :3], pose[:3, 3]
    cam = pts.reshape(-1, 3) @ R.T + T
    tris = _triangles(pts[..., 2], focal_px)
    zc = cam[:, 2]
    tris = tris[(zc[tris] > 0).all(axis=1)]
    norm = cam[:, :2] / np.where(zc > 0, zc, np.nan)[:, None]
    # the points the triangles use, in order (a mask: np.unique of the corners took 0.33 s)
    used = np.zeros(len(cam), dtype=bool)
    used[tris.reshape(-1)] = True
    used = np.flatnonzero(used)
    pix = np.full((len(cam), 2), np.nan)
    pix[used] = _to_pixels(camera, norm[used])
    c0, c1, c2 = pix[tris[:, 0]], pix[tris[:, 1]], pix[tris[:, 2]]  # (T, 2) each
    # the corners' bounds, two at a time (a min over the corner axis of (T, 3, 2) cost 0.09 s)
    lo = np.ceil(np.minimum(np.minimum(c0, c1), c2)).astype(np.int64)
    hi = np.floor(np.maximum(np.maximum(c0, c1), c2)).astype(np.int64)
    keep = ((hi - lo) < MAX_TRIANGLE_PX).all(axis=1) & (hi >= 0).all(axis=1)
    keep &= (lo[:, 0] < wc) & (lo[:, 1] < hc)
    tris, lo, hi = tris[keep], lo[keep], hi[keep]
    n0, n1, n2 = (norm[tris[:, k]] for k in range(3))
    inv_z = 1.0 / zc[tris]
    e1, e2 = n1 - n0, n2 - n0
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok_det = np.abs(det) > 0
    rays = _rays(camera).reshape(-1, 2)
    zbuf = np.full(hc * wc, np.inf)
    span = np.minimum(hi - lo, MAX_TRIANGLE_PX - 1)
    for dy in range(int(span[:, 1].max(initial=-1)) + 1):
        for dx in range(int(span[:, 0].max(initial=-1)) + 1):
            u, v = lo[:, 0] + dx, lo[:, 1] + dy
            sel = ok_det & (u <= hi[:, 0]) & (v <= hi[:, 1])
            sel &= (u >= 0) & (u < wc) & (v >= 0) & (v < hc)
            k = np.flatnonzero(sel)
            flat = v[k] * wc + u[k]
            q = rays[flat] - n0[k]
            b1 = (q[:, 0] * e2[k, 1] - q[:, 1] * e2[k, 0]) / det[k]
            b2 = (e1[k, 0] * q[:, 1] - e1[k, 1] * q[:, 0]) / det[k]
            b0 = 1.0 - b1 - b2
            inside = (b0 >= -1e-9) & (b1 >= -1e-9) & (b2 >= -1e-9)
            w = np.stack([b0, b1, b2], axis=1)[inside]
            z = 1.0 / np.sum(w * inv_z[k[inside]], axis=1)  # perspective-correct depth
            np.minimum.at(zbuf, flat[inside], z)
    z = np.where(np.isfinite(zbuf), zbuf, np.nan)
    return np.column_stack([rays * z[:, None], z]).reshape(hc, wc, 3)


@dataclass(frozen=True, eq=False)
class RGBDTake(RangeTake):
    """A read RGB-D take: the :class:`~scan2morph.io.RangeTake` on the colour grid plus the
    sensor (``intrinsics``) and, for a take of several depth frames, what fused them
    (``fusion``, e.g. a :class:`~scan2morph.scan.fusion.FusedDepth`)."""

    intrinsics: RGBDIntrinsics | None = None
    fusion: object | None = None


def check_rgbd_files(
    intr: RGBDIntrinsics,
    intrinsics_path: str | Path,
    frames: list[np.ndarray],
    paths: list[Path],
    color: np.ndarray,
    color_path: str | Path,
) -> None:
    """The cheap checks between an RGB-D take's files, before any resampling (the subject's
    check job runs them too, :mod:`scan2morph.io.check`).

    Raises
    ------
    InputError
        A depth image under the smallest size; a depth or colour image whose size differs from
        the intrinsics' ``width``/``height`` (names the intrinsics file); a frame without depth
        data.
    """
    check_image_size(frames[0].shape, paths[0], "depth")
    for name, img, cam, where in (
        ("depth", frames[0], intr.depth, ""),
        ("color", color, intr.color, "color."),
    ):
        h, w = img.shape[:2]
        if (w, h) != cam.size:
            raise InputError(
                intrinsics_path,
                f"{where}width/{where}height: {cam.size[0]}x{cam.size[1]} but the {name} image "
                f"{Path(paths[0] if name == 'depth' else color_path).name} is {w}x{h} (WxH); "
                f"are these the intrinsics of this {name} camera?",
            )
    for path, frame in zip(paths, frames, strict=True):
        if not (np.isfinite(frame) & (frame > 0)).any():
            raise InputError(path, "depth: no pixel with data (all 0 or NaN)")


def read_rgbd_take(
    depth_path,
    color_path: str | Path,
    intrinsics_path: str | Path,
    landmarks_path: str | Path | None,
    fuse: Callable | None = None,
) -> RGBDTake:
    """Read an RGB-D take into a range take on the colour image's grid.

    Parameters
    ----------
    depth_path : str, path-like or sequence of them
        16-bit depth PNG, ``.npy`` or ``.npz`` (key ``depth``), in depth units; or several
        frames (:func:`~scan2morph.io.depth_image.depth_frame_paths`).
    color_path : str or path-like
        The colour image.
    intrinsics_path : str or path-like
        The sensor's intrinsics YAML (module docstring).
    landmarks_path : str or path-like or None
        iBUG 68- (or 51-) point ``.pts`` on the colour image; None: no landmark file.
    fuse : callable, optional
        ``fuse(frames_mm, depth_camera, sources)`` -> an object with ``depth_mm`` (H, W): how
        several frames become one (:func:`scan2morph.scan.fusion.fuse_depth_frames`); needed
        when ``depth_path`` names more than one frame.

    Returns
    -------
    RGBDTake
        ``xyz`` (Hc, Wc, 3) mm in the depth camera's frame, ``color``, ``landmarks`` (68, 2) px,
        ``intrinsics`` and, from several frames, ``fusion`` (what ``fuse`` returned).

    Raises
    ------
    InputError
        From the readers; a depth or colour image whose size differs from the intrinsics'
        ``width``/``height`` (names the intrinsics file); no depth data at all; landmarks
        outside the colour image; the face check of :func:`~scan2morph.io.check_face`, which
        names a ``depth_scale_mm`` off by a factor 10 or 1000 when that factor gives a face of
        the right size; without landmarks, a nearest object outside a face's depths that
        the scale x 0.1, 10, 0.001 or 1000 puts there
        (:func:`~scan2morph.io.depth_image.check_face_depth`); from ``fuse``.
    """
    intr = read_rgbd_intrinsics(intrinsics_path)
    paths = depth_frame_paths(depth_path)
    frames = read_depth_frames(paths)
    depth = frames[0]
    color = read_color(color_path)
    check_rgbd_files(intr, intrinsics_path, frames, paths, color, color_path)
    fusion = None
    depth_mm = depth * intr.depth_scale_mm
    if len(frames) > 1:
        if fuse is None:
            raise ValueError("read_rgbd_take: several depth frames need a fuse function")
        mm = [f * intr.depth_scale_mm for f in frames]
        fusion = fuse(mm, intr.depth, [str(p) for p in paths])
        depth_mm = np.nan_to_num(fusion.depth_mm, nan=0.0)
    xyz = depth_to_color_grid(depth_mm, intr)
    take = RGBDTake(xyz=xyz, color=color, landmarks=None, intrinsics=intr, fusion=fusion)
    if landmarks_path is None:  # with landmarks, their face size names a wrong scale (below)
        check_face_depth(depth, intr.depth_scale_mm, intrinsics_path)
        return take
    landmarks = read_pts(landmarks_path)
    check_landmarks_inside(landmarks, *intr.color.size, landmarks_path)
    take = replace(take, landmarks=landmarks)
    if not complete(landmarks):  # the face is checked once the jawline is detected
        return take
    hint = f"; check depth_scale_mm = {intr.depth_scale_mm:g} in {Path(intrinsics_path).name}"
    try:
        check_face(xyz, landmarks, paths[0], landmarks_path, unit_hint=hint, camera_frame=True)
    except InputError as exc:
        factor = _scale_factor(depth, intr, landmarks)
        if factor is None:
            raise
        # a face-size problem is the scale's symptom; a landmark one would read as another cause
        gives = exc.problem.split(";")[0] if exc.problem.startswith("face size") else ""
        raise InputError(
            intrinsics_path,
            f"depth_scale_mm: {intr.depth_scale_mm:g} gives "
            f"{gives or 'no plausible face at the landmarks'}; with depth_scale_mm = "
            f"{intr.depth_scale_mm * factor:g} (x {factor:g}) the face has a plausible size: is "
            "the depth scale in mm per unit?",
        ) from None
    return take


def _scale_factor(depth: np.ndarray, intr: RGBDIntrinsics, landmarks: np.ndarray) -> float | None:
    """The factor (10, 1000, 1/10, 1/1000) of ``depth_scale_mm`` that makes the face plausible,
    tried on the failure path only; None when none does."""
    for factor in (1000.0, 0.001, 10.0, 0.1):
        scaled = RGBDIntrinsics(
            intr.depth, intr.color, intr.R, intr.T, intr.depth_scale_mm * factor
        )
        try:
            xyz = depth_to_color_grid(depth * scaled.depth_scale_mm, scaled)
            check_face(xyz, landmarks, "", "", camera_frame=True)
        except InputError:
            continue
        return factor
    return None


def _camera_dict(camera: PinholeCamera) -> dict:
    K = camera.K
    out = dict(width=camera.size[0], height=camera.size[1])
    out |= dict(fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]), cy=float(K[1, 2]))
    if camera.D.any():
        out["distortion"] = [float(v) for v in camera.D]
    return out


def write_rgbd_intrinsics(path: str | Path, intr: RGBDIntrinsics) -> None:
    """Write an RGB-D intrinsics YAML that :func:`read_rgbd_intrinsics` reads back."""
    import yaml

    from scan2morph.errors import writing

    doc = _camera_dict(intr.depth) | {"depth_scale_mm": float(intr.depth_scale_mm)}
    if intr.color is not intr.depth:
        doc["color"] = _camera_dict(intr.color) | {
            "R": [[float(v) for v in row] for row in intr.R],
            "T": [float(v) for v in intr.T],
        }
    with writing(path):
        Path(path).write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")


__all__ = [
    "PinholeCamera",
    "RGBDIntrinsics",
    "RGBDTake",
    "depth_points",
    "depth_to_color_grid",
    "project_points",
    "read_rgbd_intrinsics",
    "read_rgbd_take",
    "surface_on_camera",
    "write_rgbd_intrinsics",
]
