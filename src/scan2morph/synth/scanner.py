"""A simulated structured-light range scanner (Minolta-Vivid-like), rendered headless.

One render with pyrender (OSMesa) gives the colour image; a segmentation render of the same
scene gives, pixel for pixel, which surface each ray hits and its depth at the pixel centre
(no multisampling), from which XYZ is back-projected through the pinhole camera ``K``.

Camera frame: OpenCV's (x right, y down, z forward), mm. Pixel coordinates follow the project
convention: (0, 0) is the centre of the top-left pixel, so a camera point ``(X, Y, Z)``
projects to ``u = fx X / Z + cx``, ``v = fy Y / Z + cy``.

Defects, all seeded: Gaussian noise along the ray, spikes, dropout on dark hair (eyebrows,
scalp), pupils and small random blobs, grazing-angle dropout, and no data where a ray meets
the oral cavity or the background.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import numpy as np  # noqa: E402
import pyrender  # noqa: E402
from scipy import ndimage  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from scan2morph.geometry import surface_normals, vertex_normals  # noqa: E402
from scan2morph.offscreen import offscreen_renderer  # noqa: E402
from scan2morph.synth.head import (  # noqa: E402
    SEG_BROW,
    SEG_EYE,
    SEG_HAIR,
    SEG_SKIN,
    HeadModel,
)
from scan2morph.synth.texture import detail_image  # noqa: E402

#: Segments a scanner returns data for (before dropout): skin, brows, hair, sclera/iris.
_MEASURED = (SEG_SKIN, SEG_BROW, SEG_HAIR, SEG_EYE)
_SEG_STEP = 40  # segmentation colour = _SEG_STEP * (segment + 1) in the red channel
#: Colour of the background behind the head (dark blue-grey, like a scanning booth).
BACKGROUND_RGB = (44, 46, 56)


def camera_matrix(width: int, height: int, focal_px: float) -> np.ndarray:
    """Pinhole intrinsics with the principal point at the image centre.

    Parameters
    ----------
    width, height : int
        Image size, pixels.
    focal_px : float
        Focal length, pixels (square pixels).

    Returns
    -------
    K : (3, 3) float64
        ``[[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]]``.
    """
    return np.array(
        [[focal_px, 0.0, (width - 1) / 2.0], [0.0, focal_px, (height - 1) / 2.0], [0.0, 0.0, 1.0]]
    )


def project(K: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Project camera-frame points to pixel coordinates.

    Parameters
    ----------
    K : (3, 3) float
    points : (n, 3) float
        Camera frame, mm, ``Z > 0``.

    Returns
    -------
    (n, 2) float64
        ``(u, v)`` pixel coordinates.
    """
    p = np.asarray(points, float)
    uvw = p @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def backproject(K: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """XYZ of every pixel centre from its depth (camera Z).

    Parameters
    ----------
    K : (3, 3) float
    depth : (H, W) float
        Camera Z, mm; NaN where there is no data.

    Returns
    -------
    xyz : (H, W, 3) float64
    """
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w].astype(float)
    x = (u - K[0, 2]) / K[0, 0] * depth
    y = (v - K[1, 2]) / K[1, 1] * depth
    return np.stack([x, y, depth.astype(float)], axis=-1)


def head_pose(
    rng: np.random.Generator,
    distance_mm: float,
    sigma_deg: float,
    sigma_mm: float,
    aim: np.ndarray,
) -> np.ndarray:
    """A head->camera transform: facing the camera, plus a small random rigid motion.

    Parameters
    ----------
    rng : numpy.random.Generator
    distance_mm : float
        Camera-to-``aim`` distance along the optical axis before the random motion.
    sigma_deg : float
        Standard deviation of each rotation-vector component, degrees.
    sigma_mm : float
        Standard deviation of each translation component, mm.
    aim : (3,) float
        Head-frame point placed on the optical axis.

    Returns
    -------
    (4, 4) float64
        ``p_cam = T @ [p_head, 1]``.
    """
    flip = np.diag([1.0, -1.0, -1.0])  # head (x left-of-subject, y up, z out) -> camera
    rvec = np.deg2rad(sigma_deg) * rng.standard_normal(3)
    t_rand = sigma_mm * rng.standard_normal(3)
    R = Rotation.from_rotvec(rvec).as_matrix() @ flip
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.array([0.0, 0.0, distance_mm]) - flip @ np.asarray(aim, float) + t_rand
    return T


def shade(albedo: np.ndarray, vertices_cam: np.ndarray, normals_cam: np.ndarray) -> np.ndarray:
    """Per-vertex Lambert shading under the scanner's lamp and a key light from upper left.

    Parameters
    ----------
    albedo : (N, 3) float in [0, 1]
    vertices_cam, normals_cam : (N, 3) float
        Camera frame; unit normals pointing out of the surface.

    Returns
    -------
    (N, 3) float in [0, 1]
    """
    to_cam = -vertices_cam / np.linalg.norm(vertices_cam, axis=1, keepdims=True)
    key = np.array([-0.45, -0.55, -0.70])
    key /= np.linalg.norm(key)
    lamp = np.clip(np.sum(normals_cam * to_cam, axis=1), 0.0, 1.0)
    keyd = np.clip(normals_cam @ key, 0.0, 1.0)
    half = to_cam + key
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    spec = 0.06 * np.clip(np.sum(normals_cam * half, axis=1), 0.0, 1.0) ** 24
    light = 0.22 + 0.55 * lamp + 0.35 * keyd
    return np.clip(albedo * light[:, None] + spec[:, None], 0.0, 1.0)


def render(
    head: HeadModel,
    vertices_head: np.ndarray,
    pose: np.ndarray,
    K: np.ndarray,
    width: int,
    height: int,
    skin_texture: float = 0.0,
    texture_seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render colour, depth and segment images of a posed head.

    Parameters
    ----------
    head : HeadModel
        Topology, segments and albedo.
    vertices_head : (N, 3) float
        Deformed vertices, head frame, mm.
    pose : (4, 4) float
        Head -> camera.
    K : (3, 3) float
        Intrinsics (project convention).
    width, height : int
    skin_texture : float
        Strength of the skin's freckles and mottling, fixed to the skin
        (:func:`~scan2morph.synth.texture.skin_detail`); 0 = the flat albedo.
    texture_seed : int
        The subject's skin-detail seed.

    Returns
    -------
    color : (H, W, 3) uint8
        Shaded image (antialiased), background dark grey.
    depth : (H, W) float64
        Camera Z at each pixel centre, mm; NaN on the background.
    segment : (H, W) int8
        ``SEG_*`` code of the surface each pixel's centre ray meets; -1 on the background.
    """
    v_cam = vertices_head @ pose[:3, :3].T + pose[:3, 3]
    colors = shade(head.albedo, v_cam, vertex_normals(v_cam, head.faces, fill=0.0))
    color, depth, seg = render_colors(head, v_cam, colors, K, (width, height))
    if skin_texture > 0:
        detail = detail_image(
            seg == SEG_SKIN, v_cam, head.faces, head.vertices, K, texture_seed, skin_texture
        )
        color = np.clip(np.rint(color * detail), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(color), depth, seg


class _OrderedScene(pyrender.Scene):
    """A pyrender scene that draws its meshes in the order they were added.

    pyrender draws the mesh nodes in the iteration order of a set (the nodes' ids, that is their
    memory addresses), sorted by the distance of each node's origin to the camera. The
    segments' nodes all sit at the origin, so where surfaces of two segments lie at the same
    depth the segment a pixel showed depended on where Python had put the nodes: the same take
    rendered twice in one process could differ in a few pixels. Listed in the order added, the
    first-added surface wins a tie of depths every time.
    """

    def __init__(self, **kwargs):
        self._order: list = []
        super().__init__(**kwargs)

    def add_node(self, node, parent_node=None):
        super().add_node(node, parent_node)
        self._order.append(node)

    @property
    def mesh_nodes(self) -> list:
        """The mesh nodes, in the order added."""
        return [n for n in self._order if n in self._mesh_nodes]


def render_colors(
    head: HeadModel,
    v_cam: np.ndarray,
    colors: np.ndarray,
    K: np.ndarray,
    size: tuple[int, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pinhole render (pyrender, OSMesa) of a head with per-vertex colours.

    Parameters
    ----------
    head : HeadModel
        Topology and segments.
    v_cam : (N, 3) float
        Vertices in the camera frame (OpenCV's: x right, y down, z forward), mm.
    colors : (N, 3) float
        Per-vertex RGB in [0, 1] (flat: no lighting is added by the renderer).
    K : (3, 3) float
        Intrinsics (project convention).
    size : (int, int)
        Image ``(width, height)``, px.

    Returns
    -------
    color : (H, W, 3) uint8
        Interpolated vertex colours, :data:`BACKGROUND_RGB` behind the head.
    depth : (H, W) float64
        Camera Z at each pixel centre, mm; NaN on the background.
    segment : (H, W) int8
        ``SEG_*`` code of the surface each pixel's centre ray meets; -1 on the background.
    """
    scene = _OrderedScene(
        bg_color=np.array([*BACKGROUND_RGB, 255]) / 255.0, ambient_light=np.ones(3)
    )
    seg_map = {}
    for code in np.unique(head.segment):
        faces = head.faces[head.segment == code]
        used, inv = np.unique(faces, return_inverse=True)
        rgba = np.concatenate([colors[used], np.ones((len(used), 1))], axis=1)
        prim = pyrender.Primitive(
            positions=v_cam[used].astype(np.float32),
            indices=inv.reshape(-1, 3).astype(np.uint32),
            color_0=rgba.astype(np.float32),
            mode=pyrender.constants.GLTF.TRIANGLES,
        )
        node = scene.add(pyrender.Mesh([prim]))
        seg_map[node] = (_SEG_STEP * (int(code) + 1), 0, 0)
    z_mid = float(np.median(v_cam[:, 2]))
    cam = pyrender.IntrinsicsCamera(
        fx=K[0, 0],
        fy=K[1, 1],
        cx=K[0, 2] + 0.5,  # OpenGL samples pixel centres at (i + 0.5)
        cy=K[1, 2] + 0.5,
        znear=max(z_mid - 600.0, 1.0),
        zfar=z_mid + 600.0,
    )
    scene.add(cam, pose=np.diag([1.0, -1.0, -1.0, 1.0]))  # OpenCV camera -> OpenGL camera
    r = offscreen_renderer(*size)
    flags = pyrender.RenderFlags.SKIP_CULL_FACES
    color, _ = r.render(scene, flags=flags | pyrender.RenderFlags.FLAT)
    seg_rgb, depth = r.render(scene, flags=flags | pyrender.RenderFlags.SEG, seg_node_map=seg_map)
    seg = np.rint(seg_rgb[..., 0] / _SEG_STEP).astype(np.int8) - 1
    depth = np.where(depth > 0, depth.astype(np.float64), np.nan)
    seg[~np.isfinite(depth)] = -1
    return color, depth, seg


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], cell: float) -> np.ndarray:
    """Unit-variance-ish smooth random field with blobs of about ``cell`` pixels."""
    h, w = shape
    gh, gw = int(np.ceil(h / cell)) + 2, int(np.ceil(w / cell)) + 2
    g = rng.standard_normal((gh, gw))
    yy = np.arange(h) / cell
    xx = np.arange(w) / cell
    Y, X = np.meshgrid(yy, xx, indexing="ij")
    return ndimage.map_coordinates(g, [Y, X], order=3, mode="nearest")


@dataclass(frozen=True)
class ScanDefects:
    """A simulated range scanner's defects (:func:`scan`).

    Attributes
    ----------
    noise_mm : float
        Standard deviation of the noise along each pixel's ray, mm.
    spike_fraction : float
        Fraction of the measured pixels displaced along their ray by ``spike_mm`` x U(0.5, 1.5),
        towards or away from the camera at random.
    spike_mm : float
    hole_blobs : int
        Number of random round holes (radius 1.5 to 4 mm on the face).
    grazing_deg : float
        Pixels whose surface normal is farther than this from the view ray are dropped.
    skin_texture, texture_seed
        The skin detail (see :func:`render`).
    """

    noise_mm: float = 0.1
    spike_fraction: float = 0.001
    spike_mm: float = 30.0
    hole_blobs: int = 4
    grazing_deg: float = 75.0
    skin_texture: float = 0.0
    texture_seed: int = 0


def scan(
    head: HeadModel,
    vertices_head: np.ndarray,
    pose: np.ndarray,
    K: np.ndarray,
    width: int,
    height: int,
    rng: np.random.Generator,
    defects: ScanDefects | None = None,
) -> dict:
    """Scan a posed head: XYZ with realistic defects and the colour image.

    Parameters
    ----------
    head : HeadModel
    vertices_head : (N, 3) float
        Deformed vertices, head frame, mm.
    pose : (4, 4) float
        Head -> camera.
    K : (3, 3) float
    width, height : int
    rng : numpy.random.Generator
        Drives every defect.
    defects : ScanDefects, optional
        Noise, spikes, holes, the grazing-angle dropout and the skin detail (default
        :class:`ScanDefects`'s).

    Returns
    -------
    dict
        ``xyz`` (H, W, 3) float64 mm, NaN = no data; ``color`` (H, W, 3) uint8;
        ``segment`` (H, W) int8 (-1 = background); ``depth`` (H, W) float64, exact camera Z.
    """
    d = ScanDefects() if defects is None else defects
    noise_mm, spike_fraction, spike_mm = d.noise_mm, d.spike_fraction, d.spike_mm
    hole_blobs, grazing_deg = d.hole_blobs, d.grazing_deg
    color, depth, seg = render(
        head, vertices_head, pose, K, width, height, d.skin_texture, d.texture_seed
    )
    xyz_true = backproject(K, depth)
    valid = np.isin(seg, _MEASURED)  # no data from the background, the cavity or a pupil
    xyz = np.where(valid[..., None], xyz_true, np.nan)

    # grazing angle (and jump edges, whose finite-difference normals are grazing)
    n = surface_normals(xyz)
    ray = xyz / np.linalg.norm(xyz, axis=-1, keepdims=True)
    cosang = -np.sum(n * ray, axis=-1)
    valid &= np.nan_to_num(cosang, nan=-1.0) >= np.cos(np.deg2rad(grazing_deg))

    # dark hair drops out in ragged patches
    cell = max(2.0, width / 160.0)
    valid &= ~((seg == SEG_BROW) & (_smooth_noise(rng, seg.shape, cell) > -0.35))
    valid &= ~((seg == SEG_HAIR) & (_smooth_noise(rng, seg.shape, 2 * cell) > -1.3))
    # random round holes
    cand = np.flatnonzero(valid & (seg == SEG_SKIN))
    if hole_blobs > 0 and cand.size:
        centres = rng.choice(cand, size=int(hole_blobs), replace=True)
        radius_mm = rng.uniform(1.5, 4.0, size=int(hole_blobs))
        vv, uu = np.divmod(centres, width)
        rad_px = radius_mm * K[0, 0] / depth.reshape(-1)[centres]
        yy, xx = np.mgrid[0:height, 0:width]
        for cy, cx, rp in zip(vv, uu, rad_px, strict=True):
            r0 = int(np.ceil(rp))
            ys, xs = slice(max(cy - r0, 0), cy + r0 + 1), slice(max(cx - r0, 0), cx + r0 + 1)
            disk = (yy[ys, xs] - cy) ** 2 + (xx[ys, xs] - cx) ** 2 <= rp**2
            valid[ys, xs] &= ~disk

    # noise along the ray, then spikes
    rng_noise = rng.standard_normal(depth.shape)
    dist = np.linalg.norm(xyz_true, axis=-1) + noise_mm * rng_noise
    idx = np.flatnonzero(valid)
    n_spikes = int(round(spike_fraction * idx.size))
    if n_spikes:
        sp = rng.choice(idx, size=n_spikes, replace=False)
        sign = rng.choice(np.array([-1.0, 1.0]), size=n_spikes)
        dist.reshape(-1)[sp] += sign * spike_mm * rng.uniform(0.5, 1.5, size=n_spikes)
    xyz = np.where(valid[..., None], np.nan_to_num(ray) * dist[..., None], np.nan)

    # a little sensor noise on the colour
    c = color.astype(np.float64) + 1.5 * rng.standard_normal(color.shape)
    color = np.clip(np.rint(c), 0, 255).astype(np.uint8)
    return {"xyz": xyz, "color": color, "segment": seg, "depth": depth}
