"""Headless rendering of face meshes with pyrender (OSMesa or EGL, on the CPU).

The view is derived from the mesh, never from an axis convention: the camera looks against the
area-weighted mean normal (the face's front), with ``up`` given by the caller (for a face, from
chin to brows) or, failing that, the mesh's longest extent across the view.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import numpy as np  # noqa: E402
import pyrender  # noqa: E402
import trimesh  # noqa: E402

from scan2morph.errors import InputError  # noqa: E402
from scan2morph.offscreen import offscreen_renderer  # noqa: E402


def front_direction(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vector out of the face: the normalised area-weighted sum of face normals.

    Parameters
    ----------
    vertices : (V, 3) float, mm (NaN rows are ignored with the faces that use them).
    faces : (F, 3) int, counter-clockwise seen from the front.
    """
    tri = vertices[faces]
    ok = np.all(np.isfinite(tri), axis=(1, 2))
    n = np.cross(tri[ok, 1] - tri[ok, 0], tri[ok, 2] - tri[ok, 0]).sum(axis=0)
    norm = np.linalg.norm(n)
    if norm == 0:
        raise InputError("render", "mesh has no finite, non-degenerate faces")
    return n / norm


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """OpenGL camera pose (4, 4): camera at ``eye`` looking at ``target``, y towards ``up``."""
    z = eye - target
    z = z / np.linalg.norm(z)
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-9:  # up parallel to the view: pick any perpendicular
        x = np.cross(np.eye(3)[np.argmin(np.abs(z))], z)
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, eye
    return pose


@dataclass(frozen=True)
class MeshLook:
    """How a rendered mesh is coloured.

    Attributes
    ----------
    colors : (V, 3) float in [0, 1], optional
        Per-vertex colors (linear; e.g. a colormap of distances).
    texture, uv : (H, W, 3) uint8 and (V, 2), optional
        Texture image and texture coordinates (image convention: v down).
    wireframe : bool
        Draw the triangle edges only.
    """

    colors: np.ndarray | None = None
    texture: np.ndarray | None = None
    uv: np.ndarray | None = None
    wireframe: bool = False


@dataclass(frozen=True)
class Framing:
    """Where a rendered mesh is seen from.

    Attributes
    ----------
    up : (3,) float, optional
        Direction that should point up in the image.
    front : (3,) float, optional
        Direction from the mesh towards the camera; default :func:`front_direction`.
    yaw_deg : float
        Turn the camera about ``up`` (degrees), e.g. 30 for a three-quarter view.
    center, radius : optional
        Default the bounding sphere of the finite vertices (pass the same values to render
        several meshes at one scale).
    """

    up: np.ndarray | None = None
    front: np.ndarray | None = None
    yaw_deg: float = 0.0
    center: np.ndarray | None = None
    radius: float | None = None


def render_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    look: MeshLook | None = None,
    framing: Framing | None = None,
    size: tuple[int, int] = (480, 480),
) -> np.ndarray:
    """Render a mesh to an RGB image.

    Parameters
    ----------
    vertices : (V, 3) float, mm. Faces touching a non-finite vertex are not drawn.
    faces : (F, 3) int.
    look : MeshLook, optional
        Colours, texture or wireframe (default: shaded grey).
    framing : Framing, optional
        The view (default: from the front, the whole mesh).
    size : (width, height)

    Returns
    -------
    image : (height, width, 3) uint8
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    keep = np.all(np.isfinite(vertices[faces]), axis=(1, 2))
    if not keep.any():
        raise InputError("render", "nothing to draw: no face has three finite vertices")
    faces = faces[keep]
    safe = np.where(np.isfinite(vertices), vertices, 0.0)
    lk, fr = look or MeshLook(), framing or Framing()
    center, radius, front, up = _framing(
        vertices, safe, faces, fr.center, fr.radius, fr.front, fr.up, fr.yaw_deg
    )
    scene = pyrender.Scene(bg_color=[1.0, 1.0, 1.0, 1.0], ambient_light=[0.35, 0.35, 0.35])
    scene.add(_mesh_node(safe, faces, lk.colors, lk.texture, lk.uv, lk.wireframe))
    w, h = size
    _add_camera_and_light(scene, center, radius, front, up, w / h)
    flags = pyrender.RenderFlags.SKIP_CULL_FACES
    image, _ = offscreen_renderer(w, h).render(scene, flags=flags)
    return np.ascontiguousarray(image[:, :, :3])


def _framing(vertices, safe, faces, center, radius, front, up, yaw_deg):
    """The view's ``center``, ``radius``, ``front`` and ``up`` (those not given, from the mesh),
    the camera turned ``yaw_deg`` about ``up``."""
    used = np.unique(faces)
    if center is None:
        center = safe[used].mean(axis=0)
    if radius is None:
        radius = float(np.linalg.norm(safe[used] - center, axis=1).max())
    if front is None:
        front = front_direction(vertices, faces)
    if up is None:
        pts = safe[used] - center
        pts = pts - np.outer(pts @ front, front)
        up = np.linalg.svd(pts, full_matrices=False)[2][0]
    up = np.asarray(up, float) - np.dot(up, front) * front
    up /= np.linalg.norm(up)
    if yaw_deg:
        a = np.radians(yaw_deg)
        side = np.cross(up, front)
        front = np.cos(a) * front + np.sin(a) * side
    return center, radius, front, up


def _mesh_node(safe, faces, colors, texture, uv, wireframe) -> pyrender.Mesh:
    """The mesh as a pyrender node: textured, coloured per vertex, or a neutral skin tone."""
    mesh = trimesh.Trimesh(safe, faces, process=False)
    if texture is not None and uv is not None:
        uv_gl = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])
        from PIL import Image

        # An explicit PBR material: trimesh's default one scales the texture by 0.4 and makes
        # it metallic, which renders the face at about half its brightness.
        material = trimesh.visual.material.PBRMaterial(
            baseColorTexture=Image.fromarray(texture),
            metallicFactor=0.0,
            roughnessFactor=0.8,
            doubleSided=True,
        )
        mesh.visual = trimesh.visual.TextureVisuals(uv=uv_gl, material=material)
    elif colors is not None:
        rgba = np.column_stack([np.clip(colors, 0, 1), np.ones(len(colors))])
        mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=(rgba * 255).astype(np.uint8))
    material = None
    if colors is None and texture is None:
        material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=[0.78, 0.74, 0.70, 1.0],
            metallicFactor=0.0,
            roughnessFactor=0.8,
            doubleSided=True,
        )
    return pyrender.Mesh.from_trimesh(
        mesh, material=material, wireframe=wireframe, smooth=not wireframe
    )


def _add_camera_and_light(scene, center, radius, front, up, aspect: float) -> None:
    """A 30 degree camera framing the sphere (``center``, ``radius``) from ``front``, and a key
    light above and to the side of it."""
    fov = np.radians(30.0)
    dist = radius / np.sin(fov / 2) * 1.05
    pose = look_at(center + front * dist, center, up)
    scene.add(
        pyrender.PerspectiveCamera(yfov=fov, aspectRatio=aspect, znear=dist * 0.2, zfar=dist * 3),
        pose=pose,
    )
    key = look_at(center + dist * (front + 0.4 * up + 0.3 * np.cross(up, front)), center, up)
    scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=2.5), pose=key)
