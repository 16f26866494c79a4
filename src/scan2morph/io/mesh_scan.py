"""Mesh takes: a textured mesh scan (OBJ + MTL + texture, PLY, glTF/GLB) -> a range take.

The mesh is read with trimesh and rendered headlessly (pyrender, OSMesa) through a virtual
pinhole camera placed in front of the face. The camera looks along the face's frontal direction,
found from the surface alone (:mod:`scan2morph.io.mesh_view`: one overall normal sign, the nose
tip as the most protruding point, the face's symmetry plane and the least-squares plane of the
face around the tip; the landmarks' nose tip replaces the surface's). It is centred on the
landmarks' centroid, its image x axis along the outer eye corners (iBUG 37 -> 46, so that 37
is on the image's left), ``distance_mm`` away, with a focal length giving ``pixel_mm`` mm per
pixel at that distance (by default chosen so that the landmarks span ``face_share`` of the
image). One render gives the colour image (texture or vertex colours, unlit; a mesh with neither is
shaded grey, lit from the camera) and the depth at
every pixel centre, back-projected to XYZ in the **mesh's frame** (mm): an organised range
image, pixel to pixel with the colour. The 68 3D landmarks are projected with the same camera.

Landmark file (optional): 68 lines ``x y z`` (iBUG-68 order, the mesh's frame and units), or
the 51 without the jawline; blank lines and lines starting with ``#`` are skipped. Without all
68 the camera is found from the surface alone (:func:`~scan2morph.io.mesh_view.surface_camera`)
and the landmarks stage detects the missing points on the render.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import numpy as np  # noqa: E402

from scan2morph.errors import InputError  # noqa: E402
from scan2morph.geometry import finite_points, lambert_grey  # noqa: E402
from scan2morph.io.image import read_color  # noqa: E402
from scan2morph.io.landmarks import (  # noqa: E402
    as_ibug68,
    complete,
    count_problem,
    refuse_left_out,
)
from scan2morph.io.mesh_distance import surface_distance  # noqa: E402
from scan2morph.io.mesh_file import (  # noqa: E402
    ObjMaterials,
    check_format,
    check_obj_materials,
    check_obj_text,
    check_ply_text,
    load_problem,
    referenced_textures,
    stand_in_problem,
    uv_problem,
)
from scan2morph.io.mesh_units import (  # noqa: E402
    MESH_EXTENT_MM,
    check_landmark_units,
    check_mesh_extents,
    check_mesh_size,
)
from scan2morph.io.mesh_view import (  # noqa: E402
    face_camera,
    face_view,
    nonzero_triangles,
    surface_camera,
)
from scan2morph.io.rgbd import PinholeCamera, depth_points  # noqa: E402
from scan2morph.io.take import RangeTake, check_face, check_landmarks_inside  # noqa: E402
from scan2morph.io.text_file import utf8_text  # noqa: E402
from scan2morph.io.uv_orientation import orient_texture  # noqa: E402

log = logging.getLogger("scan2morph")
#: Mesh file suffixes trimesh reads for us.
MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf")
#: Default virtual camera (config section ``mesh_camera``).
DEFAULT_MESH_CAMERA = {
    "width": 640,
    "height": 480,
    "distance_mm": 1000.0,
    "pixel_mm": None,
    "face_share": 0.6,
}
#: A landmark farther than this from the mesh surface is "off the mesh", mm.
MAX_LANDMARK_OFFSET_MM = 5.0
#: The colour source of a geometry-only mesh (``/takes/{take}/camera/color_source``): its render
#: is the surface's shading, no skin texture.
SHADED = "shading"
#: Colour of pixels the mesh does not cover (dark blue-grey).
BACKGROUND_RGB = (44, 46, 56)


@dataclass(frozen=True, eq=False)
class MeshTake(RangeTake):
    """A rendered mesh take: the :class:`~scan2morph.io.RangeTake` plus its virtual camera.

    Attributes
    ----------
    K : (3, 3) float64
        Intrinsics of the virtual camera, px.
    pose : (4, 4) float64
        Mesh frame -> camera frame (OpenCV axes), mm.
    size : (int, int)
        Image (width, height), px.
    report : dict
        Vertex and face counts, the colour source (``texture``, ``vertex colours`` or
        ``shading``), the coverage, the pixel size (mm), the
        camera's view direction (mesh frame) and the face's symmetry residual (mm).
    landmarks_3d : (68, 3) float64 or None
        The landmark file's points, mm in the mesh's frame (NaN rows for the jawline of a
        51-point file); None without a landmark file.
    """

    K: np.ndarray = field(default_factory=lambda: np.eye(3))
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    size: tuple[int, int] = (0, 0)
    report: dict = field(default_factory=dict)
    landmarks_3d: np.ndarray | None = None


def read_mesh(path: str | Path, texture: str | Path | None = None):
    """Read a textured or vertex-coloured triangle mesh.

    Parameters
    ----------
    path : str or path-like
        OBJ (+ MTL + texture), PLY or glTF/GLB, in mm.
    texture : str or path-like, optional
        A texture image for a mesh with UV coordinates that names none (or another one).

    Returns
    -------
    trimesh.Trimesh
        With ``visual`` holding the texture (and UVs), vertex colours, or nothing (``kind``
        None: geometry only).

    Raises
    ------
    InputError
        Missing, empty or unreadable file, bytes of another format than its suffix, an OBJ
        face line cut short or indexing vertex 0 (0-based faces) or past the vertices, an
        ASCII PLY cut short, no faces (a point cloud), a NaN or infinite vertex, fewer than 3
        triangles of non-zero area, a missing MTL or texture the file references (unless the
        sheet gives the texture), a ``texture`` given for a mesh without UVs.

    Notes
    -----
    A mesh without texture and vertex colours (geometry only, or a material with a colour and
    no image) is returned without colour: :func:`read_mesh_take` renders it with shading.
    """

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected an OBJ, PLY or glTF/GLB mesh)")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(path, f"mesh: unknown format {path.suffix!r} (expected {MESH_SUFFIXES})")
    if path.stat().st_size == 0:
        raise InputError(
            path, "mesh: the file is empty (0 bytes; expected an OBJ, PLY or glTF/GLB)"
        )
    check_format(path)
    materials = None
    if path.suffix.lower() == ".ply":
        check_ply_text(path)
    if path.suffix.lower() == ".obj":
        data = path.read_bytes()  # once for both checks (a scan's OBJ may be hundreds of MB)
        check_obj_text(path, data)
        materials = check_obj_materials(path, data)
    try:
        loaded = _load(path, materials)
    except Exception as exc:  # trimesh raises many kinds on corrupt files
        raise InputError(path, load_problem(exc, path)) from None
    faces = getattr(loaded, "faces", None)
    if faces is None or len(faces) == 0:
        n = len(getattr(loaded, "vertices", []))
        raise InputError(
            path, f"mesh: no faces ({n} vertices: a point cloud?); expected a triangle mesh"
        )
    bad = np.flatnonzero(~finite_points(np.asarray(loaded.vertices)))
    if len(bad):
        raise InputError(
            path,
            f"vertices: {len(bad)} of {len(loaded.vertices)} have a NaN or infinite coordinate "
            f"(the first: vertex {bad[0] + 1}); expected finite numbers",
        )
    nonzero_triangles(loaded, str(path))
    visual = _colour_visual(loaded, path, texture, materials)
    if visual is not loaded.visual:  # a vertex-coloured or geometry-only mesh is kept as read
        loaded.visual = visual
    return loaded


def _load(path: Path, materials: ObjMaterials | None):
    """trimesh's mesh of the file; an OBJ whose text holds ``mtllib`` before its ``mtllib`` line
    (a comment: ``# converted by mtllib-tool``) read with that line put first (trimesh takes the
    name after the text's first ``mtllib``, and would read no material)."""
    import io

    import trimesh

    if materials is None or not materials.misread or materials.mtllib is None:
        return trimesh.load(path, force="mesh", process=False)
    text = f"mtllib {materials.mtllib}\n".encode() + path.read_bytes()
    resolver = trimesh.resolvers.FilePathResolver(path)
    return trimesh.load(
        io.BytesIO(text), file_type="obj", resolver=resolver, force="mesh", process=False
    )


def _colour_visual(loaded, path: Path, texture, materials: ObjMaterials | None = None):
    """The visuals :func:`read_mesh` returns: the sheet's ``texture`` on the mesh's UVs, the
    file's own texture (unlit), its vertex colours, or none (geometry only: an OBJ whose
    materials give colours, ``Kd``, and no image is no texture, however many they are)."""
    import trimesh

    visual = loaded.visual
    uv = getattr(visual, "uv", None)
    if texture is not None:
        if uv is None or len(uv) != len(loaded.vertices):
            raise InputError(
                path, f"mesh: a texture ({Path(texture).name}) is given but the mesh has no UVs"
            )
        from PIL import Image

        return _unlit_texture(uv, Image.fromarray(read_color(texture, "texture")))
    if visual.kind != "texture":
        return visual
    if materials is not None and materials.colour_only:
        return trimesh.visual.ColorVisuals(loaded)
    material = visual.material
    image = getattr(material, "image", None) or getattr(material, "baseColorTexture", None)
    if uv is not None and (why := stand_in_problem(path, image, materials)):  # its grey stand-in
        raise InputError(
            path,
            f"{why}; put the MTL and its texture beside the OBJ or give the texture in the "
            "sheet's texture column",
        )
    if image is not None and uv is None:  # a face line mixing forms drops every UV
        raise InputError(path, uv_problem(path))
    if image is not None:
        return _unlit_texture(uv, image)
    if names := referenced_textures(path):
        found = (path.parent / names[0]).is_file()
        why = "which cannot be read as an image (corrupt?)" if found else "which is missing"
        raise InputError(
            path,
            f"texture: the mesh has UVs but no texture image (the material names "
            f"{names[0]!r}, {why}); put the texture beside the MTL or name it in "
            "the sheet's texture column",
        )
    return trimesh.visual.ColorVisuals(loaded)  # no texture named: geometry only


def _unlit_texture(uv: np.ndarray, image):
    """Texture visuals whose rendered colour is the texel itself (an OBJ's ``Kd`` or a glTF's
    base colour factor would scale it: a scan's texture already holds the measured colour)."""
    import trimesh

    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=image, baseColorFactor=[255, 255, 255, 255]
    )
    return trimesh.visual.TextureVisuals(uv=uv, material=material)


#: Numbers a landmark line may hold: ``x y z``, and the point clouds MeshLab and CloudCompare
#: save (``.xyz``) with normals (``nx ny nz``), colours (``r g b`` or ``r g b a``) or both after it.
POINT_COLUMNS = (3, 6, 7, 9, 10)


def read_landmarks3d(path: str | Path) -> np.ndarray:
    """Read 3D landmarks: 68 (iBUG-68) or 51 (without the jawline) lines ``x y z`` (``#``
    comments and blank lines skipped; normals or colours after them, as a point cloud saved by
    MeshLab or CloudCompare holds them, are not read: :data:`POINT_COLUMNS`).

    Returns
    -------
    (68, 3) float64
        In the mesh's frame and units; NaN rows for the jawline of a 51-point file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected 68 or 51 lines 'x y z' of 3D landmarks)")
    text = utf8_text(path, bom=True)  # a BOM, as Windows editors save
    refuse_left_out(path, text)
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.replace(",", " ").split()
        try:
            values = [float(v) for v in parts]
        except ValueError:
            pts = line.split(":")[0].strip() in ("version", "n_points")  # a 2D .pts header
            hint = " (an iBUG .pts of 2D image points? a mesh take needs 3D points on the mesh)"
            raise InputError(
                path, f"line {number}: expected 'x y z' numbers, got {line[:40]!r}{hint * pts}"
            ) from None
        if len(values) not in POINT_COLUMNS or not np.isfinite(values[:3]).all():
            raise InputError(
                path, f"line {number}: expected 3 finite numbers (x y z), got {line[:40]!r}"
            )
        rows.append(values[:3])
    if problem := count_problem(len(rows), "points (lines 'x y z')"):
        raise InputError(path, f"got {problem}")
    return as_ibug68(np.array(rows, dtype=np.float64))


def _check_on_mesh(mesh, lm3: np.ndarray, mesh_path, landmarks_path) -> None:
    """Refuse landmarks off the mesh or of another face."""
    given = np.flatnonzero(np.isfinite(lm3).all(axis=1))
    dist = np.full(len(lm3), 0.0)
    # exact distances in float64 (open3d's ray-casting scene measured in float32, and its
    # import cost the take 0.35 CPU-s)
    dist[given] = surface_distance(mesh.vertices, mesh.faces, lm3[given], MAX_LANDMARK_OFFSET_MM)
    far = dist > MAX_LANDMARK_OFFSET_MM
    if far.any():
        k = int(np.argmax(dist))
        raise InputError(
            landmarks_path,
            f"landmarks: point {k + 1} lies {dist[k]:.3g} mm from the mesh {Path(mesh_path).name} "
            f"({int(far.sum())} points farther than {MAX_LANDMARK_OFFSET_MM:g} mm): are they of "
            "this mesh, in its frame and units?",
        )


def view_direction(mesh, lm3: np.ndarray | None = None, source: str = "mesh") -> np.ndarray:
    """The direction a frontal camera looks at the face from (:func:`~.mesh_view.face_view`).

    Found from the surface: one overall normal sign, the nose tip as the most protruding point,
    the face's symmetry plane and the least-squares plane of the face around the tip. Given
    landmarks, their nose tip (iBUG 31) replaces the surface's.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The scan, mm, any frame and winding.
    lm3 : (68, 3) float, optional
        iBUG-68 landmarks, mm.
    source : str
        The mesh file, for messages.

    Returns
    -------
    (3,) float64
        Unit vector from the camera into the face, in the mesh's frame.
    """
    tip = None if lm3 is None else np.asarray(lm3, dtype=np.float64)[30]
    return face_view(mesh, tip, str(source)).direction


def virtual_camera(
    lm3: np.ndarray, forward: np.ndarray, settings: dict
) -> tuple[np.ndarray, np.ndarray]:
    """The virtual camera in front of a face (module docstring).

    Parameters
    ----------
    lm3 : (68, 3) float
        iBUG-68 landmarks, mm.
    forward : (3,) float
        Unit view direction (:func:`view_direction`): the camera's z axis.
    settings : dict
        ``width``, ``height``, ``distance_mm``, ``pixel_mm`` (None: automatic), ``face_share``.

    Returns
    -------
    K : (3, 3) float64, px
    pose : (4, 4) float64
        Mesh frame -> camera frame (x right, y down, z forward), mm; x along the outer eye
        corners (iBUG 37 -> 46) in the image plane.
    """
    z = np.asarray(forward, dtype=np.float64)
    x = lm3[45] - lm3[36]
    x = x - (x @ z) * z
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    centre = lm3.mean(axis=0)
    # the landmarks' extent across the camera fills face_share of the image (without pixel_mm)
    extent = np.ptp((lm3 - centre) @ R[:2].T, axis=0)
    return face_camera(R, centre, (float(extent[0]), float(extent[1])), settings)


def _check_not_mirrored(lm3: np.ndarray, pose: np.ndarray, landmarks_path) -> None:
    """Refuse 3D landmarks whose chin lies above the eyes in the landmark camera's image."""
    eyes_to_chin = pose[1, :3] @ (lm3[8] - (lm3[36] + lm3[45]) / 2)
    if eyes_to_chin < 0:  # the image is upside down: 37 -> 46 runs right to left on the face
        raise InputError(
            landmarks_path,
            "landmarks: mirrored left/right (seen from the front of the face, iBUG 37 -> 46 "
            "runs from the image's right to its left); iBUG 37 is the outer corner of the "
            "subject's right eye",
        )


def colour_source(mesh) -> str:
    """Where a read mesh's rendered colour comes from: ``texture``, ``vertex colours`` or
    ``shading`` (geometry only: :func:`shade`)."""
    return {"texture": "texture", "vertex": "vertex colours"}.get(mesh.visual.kind, SHADED)


def shade(mesh, pose: np.ndarray):
    """A geometry-only mesh coloured grey by its shading, lit from the camera.

    Lambert's law with the light at the camera: each vertex's grey is
    ``SHADE_AMBIENT + (1 - SHADE_AMBIENT) * |n . z|`` of full white, ``n`` its unit normal and
    ``z`` the camera's viewing axis (either winding gives the same picture).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Mesh frame, mm.
    pose : (4, 4) float
        Mesh frame -> camera frame (:func:`virtual_camera`).

    Returns
    -------
    trimesh.Trimesh
        A copy with vertex colours (uint8 RGBA).
    """
    import trimesh

    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    grey = lambert_grey(normals @ np.asarray(pose, dtype=np.float64)[2, :3])
    out = mesh.copy()
    rgba = np.column_stack([grey, grey, grey, np.full_like(grey, 255)])
    out.visual = trimesh.visual.ColorVisuals(out, vertex_colors=rgba)
    return out


def render_mesh(mesh, K: np.ndarray, pose: np.ndarray, size: tuple[int, int]):
    """Render a mesh's colour (unlit) and depth through a pinhole camera.

    Returns
    -------
    color : (H, W, 3) uint8
    depth : (H, W) float64
        Camera Z at each pixel centre, mm; NaN where the mesh is not seen.
    """
    import pyrender

    from scan2morph.offscreen import offscreen_renderer

    v_cam = np.asarray(mesh.vertices) @ pose[:3, :3].T + pose[:3, 3]
    posed = mesh.copy()
    posed.vertices = v_cam
    scene = pyrender.Scene(
        bg_color=np.array([*BACKGROUND_RGB, 255]) / 255.0, ambient_light=np.ones(3)
    )
    scene.add(pyrender.Mesh.from_trimesh(posed, smooth=False))
    z = v_cam[:, 2]
    cam = pyrender.IntrinsicsCamera(
        fx=K[0, 0],
        fy=K[1, 1],
        cx=K[0, 2] + 0.5,  # OpenGL samples pixel centres at (i + 0.5)
        cy=K[1, 2] + 0.5,
        znear=max(float(z.min()) - 10.0, 1.0),
        zfar=float(z.max()) + 10.0,
    )
    scene.add(cam, pose=np.diag([1.0, -1.0, -1.0, 1.0]))  # OpenCV camera -> OpenGL camera
    flags = pyrender.RenderFlags.SKIP_CULL_FACES | pyrender.RenderFlags.FLAT
    color, depth = offscreen_renderer(*size).render(scene, flags=flags)
    depth = np.where(depth > 0, depth.astype(np.float64), np.nan)
    return np.ascontiguousarray(color[..., :3]), depth


def _render_take(mesh, camera, pose, sheet_texture, mesh_path):
    """A read mesh rendered through the take's camera: ``(color, depth, report entries)``.

    A geometry-only mesh is shown by its shading (:func:`shade`, with a warning); a texture
    from the sheet (``sheet_texture``) is kept the way up it lies on the surface
    (:mod:`~scan2morph.io.uv_orientation`). The entries: ``colour`` (:func:`colour_source`)
    and, for a sheet's texture, ``uv_flipped`` and ``uv_agreement``."""
    source = colour_source(mesh)
    if source == SHADED:
        log.warning(
            "%s: no texture and no vertex colours: rendered with shading (grey, lit from the "
            "camera); texture-driven refinement is not available for this take",
            mesh_path,
        )
        mesh = shade(mesh, pose)
    K, size = camera.K, camera.size
    if sheet_texture is None or source != "texture":  # the file's own colour: seen on the mesh
        return (*render_mesh(mesh, K, pose, size), {"colour": source})
    color, depth, orientation = orient_texture(
        mesh,
        lambda m: render_mesh(m, K, pose, size),
        lambda d: depth_points(np.nan_to_num(d, nan=0.0), camera),
    )
    if orientation.flipped:
        log.warning("%s: %s", mesh_path, orientation.flip_message(Path(sheet_texture).name))
    return color, depth, {"colour": source} | orientation.as_report()


def read_mesh_take(
    mesh_path: str | Path,
    texture_path: str | Path | None,
    landmarks_path: str | Path | None,
    settings: dict | None = None,
    mm_per_unit: float = 1.0,
) -> MeshTake:
    """Read a mesh take and render it into a range take (module docstring).

    Parameters
    ----------
    mesh_path : str or path-like
        OBJ / PLY / glTF / GLB, mm.
    texture_path : str or path-like or None
        A texture image for the mesh's UVs (the sheet's optional ``texture`` column).
    landmarks_path : str or path-like or None
        68 (or 51, without the jawline) lines ``x y z`` in the mesh's frame and units; None:
        no landmarks (they are detected on the render). Without all 68, the camera is found
        from the surface alone (:func:`~.mesh_view.surface_camera`).
    settings : dict, optional
        ``width``, ``height`` (px), ``distance_mm``, ``pixel_mm`` (None: automatic) and
        ``face_share`` of the virtual camera (defaults :data:`DEFAULT_MESH_CAMERA`).
    mm_per_unit : float
        The mesh's and landmarks' unit in mm (the sheet's ``units`` column: 1 for mm, 10 for
        cm, 1000 for m); both are scaled to mm as read.

    Returns
    -------
    MeshTake
        ``xyz`` (H, W, 3) mm in the mesh's frame (scaled to mm), ``color`` (the texture or
        vertex colours, or for a geometry-only mesh its grey shading lit from the camera:
        :func:`shade`), ``landmarks`` (68, 2) px (None without a landmark file; NaN rows for
        the points a 51-point file leaves out), the camera (``K``, ``pose``, ``size``) and a
        ``report``.

    Raises
    ------
    InputError
        From :func:`read_mesh` and :func:`read_landmarks3d`; a face not 50-150 mm across the
        outer eye corners, or a mesh not 60-1000 mm across (names the unit it looks like, the
        landmark file when the mesh is a face's size, or a wrong ``units`` value:
        :mod:`~scan2morph.io.mesh_units`); landmarks off the mesh; landmarks
        whose surface faces away from the camera (mirrored: iBUG 37 must be the subject's right
        eye's outer corner); the face checks of :func:`~scan2morph.io.check_face`.
    """
    cfg = dict(DEFAULT_MESH_CAMERA) | dict(settings or {})
    mesh = read_mesh(mesh_path, texture_path)
    as_read = np.asarray(mesh.extents, dtype=np.float64)
    if mm_per_unit != 1.0:
        mesh.apply_scale(mm_per_unit)
    lm3 = None if landmarks_path is None else read_landmarks3d(landmarks_path) * mm_per_unit
    if lm3 is not None:
        check_landmark_units(lm3, mesh.extents, mesh_path, landmarks_path, mm_per_unit)
    check_mesh_extents(as_read, mm_per_unit, mesh_path)
    if lm3 is not None:
        _check_on_mesh(mesh, lm3, mesh_path, landmarks_path)
    view = face_view(mesh, None if lm3 is None else lm3[30], str(mesh_path))
    if complete(lm3):
        K, pose = virtual_camera(lm3, view.direction, cfg)
        _check_not_mirrored(lm3, pose, landmarks_path)
    else:
        K, pose = surface_camera(np.asarray(mesh.vertices), view, cfg, str(mesh_path))
    size = (int(cfg["width"]), int(cfg["height"]))
    camera = PinholeCamera(K, np.zeros(5), size)
    color, depth, colour = _render_take(mesh, camera, pose, texture_path, mesh_path)
    xyz_cam = depth_points(np.nan_to_num(depth, nan=0.0), camera)
    xyz = (xyz_cam - pose[:3, 3]) @ pose[:3, :3]  # camera -> mesh frame
    landmarks = None
    if lm3 is not None:
        lm_cam = lm3 @ pose[:3, :3].T + pose[:3, 3]
        landmarks = lm_cam[:, :2] / lm_cam[:, 2:3] * np.diag(K)[:2] + K[:2, 2]
        check_landmarks_inside(landmarks, *size, landmarks_path)
        if complete(landmarks):
            check_face(xyz, landmarks, mesh_path, landmarks_path)
    report = colour | {
        "n_vertices": int(len(mesh.vertices)),
        "n_faces": int(len(mesh.faces)),
        "coverage": float(np.isfinite(depth).mean()),
        "pixel_mm": float(cfg["distance_mm"] / K[0, 0]),
        "view_direction": [float(x) for x in view.direction],
        "symmetry_mm": view.symmetry_mm,
    }
    return MeshTake(
        xyz=xyz,
        color=color,
        landmarks=landmarks,
        K=K,
        pose=pose,
        size=size,
        report=report,
        landmarks_3d=lm3,
    )


__all__ = [
    "DEFAULT_MESH_CAMERA",
    "MESH_EXTENT_MM",
    "MeshTake",
    "check_mesh_size",
    "read_landmarks3d",
    "read_mesh",
    "read_mesh_take",
    "render_mesh",
    "view_direction",
    "virtual_camera",
]
