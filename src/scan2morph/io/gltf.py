"""glTF 2.0 binary (``.glb``) export of a textured face mesh with named morph targets.

Written with pygltflib (the JSON document and the GLB container); this module packs the
binary buffer and checks the input. The Khronos glTF validator reports no error and no warning on
the written files (``tests/unit/test_gltf_viewer.py``).

Frames. The meshes come in a **source frame** (the neutral take's scanner frame, mm). ``frame``
(a (4, 4) similarity: rotation times a scale, det > 0) maps it to the **glTF frame** in which the
positions are written; the morph stage passes the subject's head frame
(:func:`scan2morph.morph.frame.head_frame`: metres, +X to the viewer's right = the subject's
left, +Y up, +Z out of the face towards the viewer, origin between the eyes), so that a viewer
looking down -Z sees the face upright, from the front, at human size. Without a frame, the source
coordinates are only scaled to metres (``metres=True``) or left as they are.

Layout of the written file (one scene, one node, one mesh, one triangle primitive):

- node 0 (the mesh node): no transform when the positions lie near the origin (a head frame);
  otherwise (no frame: a face ~1 m from the scanner) ``translation = c``, the centre of the
  bounding box in the glTF frame, with positions stored relative to c (float32 of coordinates
  ~1 m away is spaced ~1e-4 mm; relative to c a face keeps ~1e-5 mm). ``node.extras``:
  ``source_to_gltf`` (the (4, 4) frame, row-major nested lists, so that
  ``[p_gltf, 1] = F @ [p_source, 1]``), ``source_units`` (``mm``) and ``frame`` (what the glTF
  frame is). ``asset.extras`` repeats ``frame``, ``source_to_gltf`` and the units.
- attributes ``POSITION`` (float32, with min/max), ``NORMAL`` (area-weighted vertex normals,
  unit length) and ``TEXCOORD_0`` (float32). glTF's texture coordinates have their origin at the
  top-left corner of the image with v pointing down, which is our image convention
  (u = (x + 0.5) / W, v = (y + 0.5) / H for pixel (x, y)), so uv are written unflipped.
- an embedded PNG texture, bound as ``baseColorTexture`` of a non-metallic double-sided material.
- morph targets: ``POSITION`` displacements (target minus base, in the glTF frame, taken from the
  float32-rounded base so that base + displacement rounds once; each accessor with min/max) and,
  with normals, ``NORMAL`` displacements; their names in ``mesh.extras.targetNames`` (the
  convention three.js, Babylon.js and Blender read), what each one is in
  ``mesh.extras.targetNotes`` and, for PCA component targets, the signed standard deviations
  sigma_k that weight 1 adds in ``mesh.extras.targetSigmas``; default ``mesh.weights`` all zero.
  A viewer shows ``base + sum_k w_k displacement_k``. Blender's importer makes each target a
  shape key of range 0..1 (it widens a key's range only to a non-zero default weight), so a
  target meant to be used at negative weights is written as a separate target of opposite sign.

Every buffer view starts at a multiple of 4 bytes and every accessor is tightly packed.
"""

from __future__ import annotations

from collections.abc import Mapping
from os import PathLike
from pathlib import Path

import cv2
import numpy as np
import pygltflib

from scan2morph.errors import InputError, writing
from scan2morph.geometry import TexturedMesh, check_vertex_array, face_normals, vertex_normals

_ARRAY_BUFFER = pygltflib.ARRAY_BUFFER
_ELEMENT_ARRAY_BUFFER = pygltflib.ELEMENT_ARRAY_BUFFER
_COMPONENT_DTYPES = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: Scale from our millimetres to glTF's metres (the default frame with ``metres=True``).
MM_TO_M = 1e-3
#: The positions are written relative to their bounding-box centre (a node translation) when
#: that centre lies farther from the origin than this many times the mesh's size.
_RECENTRE = 1.0


class MorphTargets(dict):
    """Morph targets for :func:`write_glb`: name -> absolute (V, 3) positions (source frame, mm),
    with the frame they are exported in and a note per target.

    A plain dict works as ``targets`` too; this one also carries ``frame`` and ``frame_name``
    (used when :func:`write_glb` gets no ``frame``), ``notes`` (name -> what the target is, written
    to ``mesh.extras.targetNotes``) and ``sigmas`` (name -> signed standard deviations of a PCA
    component at weight 1, written to ``mesh.extras.targetSigmas``) from the stage that builds
    the shapes to the writer.
    """

    def __init__(
        self,
        targets=(),
        *,
        frame=None,
        frame_name: str | None = None,
        notes: Mapping[str, str] | None = None,
        sigmas: Mapping[str, float] | None = None,
    ):
        super().__init__(targets)
        self.frame = None if frame is None else np.asarray(frame, dtype=np.float64)
        self.frame_name = frame_name
        self.notes = dict(notes or {})
        self.sigmas = {str(k): float(v) for k, v in (sigmas or {}).items()}


class _BufferBuilder:
    """Accumulates the binary buffer, its buffer views and accessors (pygltflib objects)."""

    def __init__(self):
        self.blob = bytearray()
        self.views: list[pygltflib.BufferView] = []
        self.accessors: list[pygltflib.Accessor] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        self.blob.extend(b"\x00" * (-len(self.blob) % 4))
        self.views.append(
            pygltflib.BufferView(
                buffer=0, byteOffset=len(self.blob), byteLength=len(data), target=target
            )
        )
        self.blob.extend(data)
        return len(self.views) - 1

    def accessor(self, array: np.ndarray, kind: str, target: int, minmax: bool) -> int:
        """Store a float32 (N, c) or uint32 (N,) array; min/max computed from the stored data."""
        unsigned = array.dtype == np.uint32
        stored = np.ascontiguousarray(array, dtype="<u4" if unsigned else "<f4")
        acc = pygltflib.Accessor(
            bufferView=self.view(stored.tobytes(), target),
            componentType=pygltflib.UNSIGNED_INT if unsigned else pygltflib.FLOAT,
            count=int(stored.shape[0]),
            type=kind,
        )
        if minmax:
            flat = stored.reshape(stored.shape[0], -1)
            cast = int if unsigned else float
            acc.min = [cast(v) for v in flat.min(axis=0)]
            acc.max = [cast(v) for v in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3); isolated or degenerate vertices get the mean
    normal of the whole mesh so that every NORMAL is unit length, as glTF requires."""
    n = vertex_normals(vertices, faces)
    bad = np.isnan(n[:, 0])
    if bad.any():
        overall = face_normals(vertices, faces).sum(axis=0)
        norm = np.linalg.norm(overall)
        n[bad] = overall / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
    return n


def _check_vertices(name: str, value, source: str, n_vertices: int | None) -> np.ndarray:
    return check_vertex_array(
        value, name, source, n_vertices, hint="; glTF allows no NaN, pass filled vertices"
    )


def _check_frame(frame, source: str) -> np.ndarray:
    """A (4, 4) similarity with positive determinant (a rotation times a scale, no mirror: a
    mirror would turn the counter-clockwise front faces into back faces)."""
    f = np.asarray(frame, dtype=np.float64)
    if f.shape != (4, 4) or not np.isfinite(f).all():
        raise InputError(source, f"frame: expected a finite (4, 4) transform, got shape {f.shape}")
    if not np.array_equal(f[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(source, f"frame: last row must be [0, 0, 0, 1], got {f[3].tolist()}")
    lin = f[:3, :3]
    scale = np.cbrt(np.linalg.det(lin))
    if not scale > 0 or not np.allclose(
        lin @ lin.T, scale**2 * np.eye(3), rtol=0, atol=1e-9 * scale**2
    ):
        raise InputError(
            source, "frame: expected a rotation times a positive scale (orthogonal, det > 0)"
        )
    return f


def _apply(frame: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ frame[:3, :3].T + frame[:3, 3]


def write_glb(
    path: str | PathLike[str],
    mesh: TexturedMesh,
    targets: Mapping[str, np.ndarray] | None = None,
    *,
    normals: bool = True,
    mesh_name: str = "face",
    metres: bool = True,
    frame=None,
    frame_name: str | None = None,
) -> None:
    """Write a textured triangle mesh with named morph targets as a glTF 2.0 binary.

    Parameters
    ----------
    path : path-like
        The ``.glb`` file to write (parent directory must exist).
    mesh : TexturedMesh
        The base mesh (e.g. the neutral mesh): vertices (V, 3) mm in the source frame, no NaN;
        counter-clockwise faces (glTF's front faces); optional uv (V, 2) in [0, 1] (our image
        convention, the same as glTF's) and an RGB texture (H, W, 3) uint8, embedded as PNG,
        which requires uv.
    targets : mapping name -> (V, 3) float, optional
        Morph targets as absolute vertex positions in the frame of ``vertices``; stored as
        displacements from the base, in the glTF frame. Names go to ``mesh.extras.targetNames``.
        A :class:`MorphTargets` also brings its ``frame`` and ``notes``.
    normals : bool
        Write area-weighted vertex normals (and their morph-target displacements).
    mesh_name : str
        Name of the mesh and its node.
    metres : bool
        Without a ``frame``: scale mm to m (glTF's unit), so viewers show true size.
    frame : (4, 4) float, optional
        Source frame -> glTF frame (``[p_gltf, 1] = frame @ [p_source, 1]``), a rotation times a
        positive scale plus a translation; e.g. the head frame (mm -> m). Default: the
        ``frame`` of a :class:`MorphTargets`, else ``diag(s, s, s, 1)`` (s = 0.001 with
        ``metres``, else 1).
    frame_name : str, optional
        What the glTF frame is (``node.extras.frame``, ``asset.extras.frame``).

    Raises
    ------
    InputError
        On NaN/inf or wrongly shaped vertices or targets (naming the target), faces out of range,
        uv outside [0, 1] or of the wrong shape, a texture that is not (H, W, 3) uint8, a texture
        without uv, or a frame that is not a similarity with positive determinant.
    """
    source = str(path)
    base = _check_vertices("vertices", mesh.vertices, source, None)
    n_vertices = base.shape[0]
    if n_vertices == 0:
        raise InputError(source, "vertices: the mesh has no vertices")
    tri, uv, texture = _check_mesh(mesh.faces, mesh.uv, mesh.texture, n_vertices, source)
    frame, frame_name = _resolve_frame(frame, frame_name, targets, metres, source)
    notes = dict(getattr(targets, "notes", {}))
    sigmas = dict(getattr(targets, "sigmas", {}))
    targets = {} if targets is None else dict(targets)
    checked = {
        str(name): _check_vertices(f"targets[{name!r}]", t, source, n_vertices)
        for name, t in targets.items()
    }

    world = _apply(frame, base)
    centre = _centre(world)
    local32 = (world - centre).astype(np.float32)
    local = local32.astype(np.float64)  # what a reader sees; displacements are taken from it
    buf = _BufferBuilder()
    attributes, indices, base_normals = _base_attributes(buf, local32, world, tri, uv, normals)

    target_list = [
        _target(buf, _apply(frame, t), centre, local, tri, base_normals) for t in checked.values()
    ]
    frame_rows = [[float(x) for x in row] for row in frame]
    frame_name = frame_name or "glTF frame: source_to_gltf applied to the source coordinates"
    gltf = _document(frame_rows, frame_name)
    _add_material(gltf, buf, texture, mesh_name, source)
    primitive = pygltflib.Primitive(
        attributes=attributes,
        indices=indices,
        mode=pygltflib.TRIANGLES,
        material=0,
        targets=target_list,
    )
    gltf_mesh = pygltflib.Mesh(name=mesh_name, primitives=[primitive])
    _name_targets(gltf_mesh, list(checked), notes, sigmas)
    _finish(gltf, buf, gltf_mesh, centre, frame_rows, frame_name)
    with writing(path):
        gltf.save_binary(str(path))


def _check_mesh(faces, uv, texture, n_vertices: int, source: str):
    """The faces (int64), uv and texture of :func:`write_glb`, checked."""
    tri = np.asarray(faces)
    if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] == 0:
        raise InputError(source, f"faces: expected a non-empty (F, 3) array, got shape {tri.shape}")
    if not np.issubdtype(tri.dtype, np.integer):
        raise InputError(source, f"faces: expected integer indices, got {tri.dtype}")
    if tri.min() < 0 or tri.max() >= n_vertices:
        raise InputError(
            source,
            f"faces: indices must lie in [0, {n_vertices - 1}], got [{tri.min()}, {tri.max()}]",
        )
    tri = tri.astype(np.int64)
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape != (n_vertices, 2):
            raise InputError(source, f"uv: expected shape ({n_vertices}, 2), got {uv.shape}")
        if not (np.isfinite(uv).all() and uv.min() >= 0.0 and uv.max() <= 1.0):
            raise InputError(source, "uv: expected finite texture coordinates in [0, 1]")
    if texture is not None:
        texture = np.asarray(texture)
        if texture.ndim != 3 or texture.shape[2] != 3 or texture.dtype != np.uint8:
            raise InputError(
                source,
                f"texture: expected (H, W, 3) uint8 RGB, got {texture.shape} {texture.dtype}",
            )
        if uv is None:
            raise InputError(source, "texture: given without uv (texture coordinates needed)")
    return tri, uv, texture


def _resolve_frame(frame, frame_name, targets, metres: bool, source: str):
    """The source -> glTF frame and its name: given, the targets' own, or a scale to metres."""
    if frame is None:
        frame = getattr(targets, "frame", None)
        frame_name = frame_name or getattr(targets, "frame_name", None)
    if frame is None:
        s = MM_TO_M if metres else 1.0
        frame = np.diag([s, s, s, 1.0])
        frame_name = frame_name or ("source frame, metres" if metres else "source frame")
    frame = _check_frame(frame, source)
    return frame, frame_name


def _add_material(gltf, buf, texture, mesh_name: str, source: str) -> None:
    """The mesh's one material: unlit-looking PBR, its texture embedded as PNG when given."""
    pbr = pygltflib.PbrMetallicRoughness(metallicFactor=0.0, roughnessFactor=1.0)
    if texture is not None:
        ok, png = cv2.imencode(".png", np.ascontiguousarray(texture[:, :, ::-1]))
        if not ok:  # pragma: no cover - OpenCV fails only on out-of-memory
            raise InputError(source, "texture: PNG encoding failed")
        gltf.images = [pygltflib.Image(bufferView=buf.view(png.tobytes()), mimeType="image/png")]
        gltf.samplers = [
            pygltflib.Sampler(
                magFilter=pygltflib.LINEAR,
                minFilter=pygltflib.LINEAR,
                wrapS=pygltflib.CLAMP_TO_EDGE,
                wrapT=pygltflib.CLAMP_TO_EDGE,
            )
        ]
        gltf.textures = [pygltflib.Texture(sampler=0, source=0)]
        pbr.baseColorTexture = pygltflib.TextureInfo(index=0, texCoord=0)
    gltf.materials = [
        pygltflib.Material(name=f"{mesh_name}_skin", pbrMetallicRoughness=pbr, doubleSided=True)
    ]


def _target(buf, moved, centre, local, tri, base_normals):
    """One morph target's accessors: its displacement from the base (and its normals' change
    when the base has normals)."""
    entry = pygltflib.Attributes(
        POSITION=buf.accessor(
            ((moved - centre) - local).astype(np.float32), "VEC3", _ARRAY_BUFFER, minmax=True
        )
    )
    if base_normals is not None:
        delta = _vertex_normals(moved, tri) - base_normals
        entry.NORMAL = buf.accessor(delta, "VEC3", _ARRAY_BUFFER, minmax=False)
    return entry


def _centre(world: np.ndarray) -> np.ndarray:
    """The node's translation: the bounding box's centre, or zero when the mesh is already
    about the origin (within :data:`_RECENTRE` of its size)."""
    lo, hi = world.min(axis=0), world.max(axis=0)
    centre = 0.5 * (lo + hi)
    if np.linalg.norm(centre) <= _RECENTRE * max(float(np.max(hi - lo)), 1e-300):
        centre = np.zeros(3)
    return centre


def _base_attributes(buf, local32, world, tri, uv, normals: bool):
    """The base mesh's accessors: positions, normals (when asked), uv (when given), indices;
    and the base normals (None without)."""
    attributes = pygltflib.Attributes(
        POSITION=buf.accessor(local32, "VEC3", _ARRAY_BUFFER, minmax=True)
    )
    base_normals = None
    if normals:
        base_normals = _vertex_normals(world, tri)
        attributes.NORMAL = buf.accessor(base_normals, "VEC3", _ARRAY_BUFFER, minmax=False)
    if uv is not None:
        attributes.TEXCOORD_0 = buf.accessor(uv, "VEC2", _ARRAY_BUFFER, minmax=False)
    indices = buf.accessor(tri.astype(np.uint32).ravel(), "SCALAR", _ELEMENT_ARRAY_BUFFER, True)
    return attributes, indices, base_normals


def _name_targets(mesh, names: list[str], notes: dict, sigmas: dict) -> None:
    """The morph targets' zero weights and, in ``mesh.extras``, their names, notes and sigmas."""
    if not names:
        return
    mesh.weights = [0.0] * len(names)
    mesh.extras = {"targetNames": names}
    if notes:
        mesh.extras["targetNotes"] = {k: str(notes[k]) for k in names if k in notes}
    if sigmas:
        mesh.extras["targetSigmas"] = {k: sigmas[k] for k in names if k in sigmas}


def _document(frame_rows: list, frame_name: str) -> pygltflib.GLTF2:
    """The glTF document with its asset (units and the source frame) and one scene."""
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(
            version="2.0",
            generator="scan2morph (pygltflib)",
            extras={
                "mesh_units": "m",
                "source_units": "mm",
                "frame": frame_name,
                "source_to_gltf": frame_rows,
            },
        ),
        scene=0,
        scenes=[pygltflib.Scene(nodes=[0])],
    )
    return gltf


def _finish(gltf, buf, mesh, centre, frame_rows: list, frame_name: str) -> None:
    """The mesh's node (translated to ``centre``), the accessors and the one binary buffer."""
    mesh_name = mesh.name
    gltf.meshes = [mesh]
    node = pygltflib.Node(
        name=mesh_name,
        mesh=0,
        extras={"source_to_gltf": frame_rows, "source_units": "mm", "frame": frame_name},
    )
    if centre.any():
        node.translation = [float(c) for c in centre]
    gltf.nodes = [node]
    gltf.accessors = buf.accessors
    gltf.bufferViews = buf.views
    buf.blob.extend(b"\x00" * (-len(buf.blob) % 4))
    gltf.buffers = [pygltflib.Buffer(byteLength=len(buf.blob))]
    gltf.set_binary_blob(bytes(buf.blob))


def _read_glb(path: Path) -> pygltflib.GLTF2:
    """Load a GLB container with pygltflib, after checking its header."""
    data = path.read_bytes()
    if len(data) < 20 or data[:4] != b"glTF":
        raise InputError(path, "not a binary glTF file (missing the 'glTF' magic)")
    version, total = np.frombuffer(data[4:12], "<u4")
    if version != 2 or total > len(data):
        raise InputError(path, f"header: expected glTF version 2 of {total} bytes, got v{version}")
    try:
        gltf = pygltflib.GLTF2.load_from_bytes(data)
    except Exception as err:  # noqa: BLE001 - pygltflib raises whatever its parser meets
        raise InputError(path, f"unreadable glTF: {err}") from err
    if gltf is None:
        raise InputError(path, "no JSON chunk")
    return gltf


def _read_accessor(gltf: pygltflib.GLTF2, blob: bytes, index: int) -> np.ndarray:
    """One accessor as an (count, n) or (count,) array of its component type."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    dtype = np.dtype(_COMPONENT_DTYPES[acc.componentType])
    n = _TYPE_SIZES[acc.type]
    offset = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or n * dtype.itemsize
    arr = np.ndarray(
        (acc.count, n), dtype, buffer=blob, offset=offset, strides=(stride, dtype.itemsize)
    )
    return arr.copy() if n > 1 else arr[:, 0].copy()


def read_glb_frame(path: str | PathLike[str]) -> np.ndarray:
    """The (4, 4) source -> glTF frame of a file written by :func:`write_glb`
    (``node.extras.source_to_gltf``; for the morph stage's files the head frame, neutral mm to
    head-frame m, as ``/neutral/head_frame`` in the store)."""
    path = Path(path)
    return _frame_of(path, _mesh_node(path, _read_glb(path)))


def _mesh_node(path: Path, gltf: pygltflib.GLTF2) -> pygltflib.Node:
    nodes = [n for n in gltf.nodes if n.mesh is not None]
    if not nodes:
        raise InputError(path, "nodes: no node carries a mesh")
    node = nodes[0]
    scale = node.scale if node.scale is not None else [1, 1, 1]
    if node.matrix is not None or list(scale) != [1, 1, 1] or node.rotation is not None:
        raise InputError(path, f"nodes: mesh node {node.name!r} must carry a translation only")
    index = gltf.nodes.index(node)
    if any(index in (n.children or []) for n in gltf.nodes):
        raise InputError(path, f"nodes: mesh node {node.name!r} must be a root node of the scene")
    return node


def _frame_of(path: Path, node: pygltflib.Node) -> np.ndarray:
    rows = (node.extras or {}).get("source_to_gltf")
    if rows is None:
        raise InputError(
            path, "nodes: the mesh node has no extras.source_to_gltf (not written by write_glb)"
        )
    return _check_frame(rows, str(path))


def _position(target) -> int:
    """The POSITION accessor of a morph target (pygltflib parses targets as plain dicts)."""
    return target["POSITION"] if isinstance(target, Mapping) else target.POSITION


def read_glb_targets(
    path: str | PathLike[str], frame: str = "source"
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read back the base mesh and the morph targets written by :func:`write_glb`.

    Parameters
    ----------
    path : path-like
        A ``.glb`` file holding one root mesh node (translation only) whose first primitive
        carries the targets, with ``node.extras.source_to_gltf``.
    frame : ``"source"`` or ``"gltf"``
        ``source`` (default): the coordinates :func:`write_glb` was given (for the morph stage's
        files: the neutral frame, mm, as ``/neutral/vertices`` and ``/visemes/{take}/model``);
        ``gltf``: as a viewer places them (the head frame, metres).

    Returns
    -------
    base : (V, 3) float64
        Base vertex positions (the node translation and, for ``source``, the inverse frame
        applied).
    targets : dict name -> (V, 3) float64
        Absolute positions of each morph target at weight 1 (base plus its displacement), in
        file order.

    Raises
    ------
    InputError
        If the file is not GLB, has no mesh node, the mesh node is rotated, scaled or a child, has
        no frame, or ``frame`` is unknown.
    """
    if frame not in ("source", "gltf"):
        raise InputError(str(path), f"frame: {frame!r} unknown (expected 'source' or 'gltf')")
    path = Path(path)
    gltf = _read_glb(path)
    blob = gltf.binary_blob() or b""
    node = _mesh_node(path, gltf)
    to_gltf = _frame_of(path, node)
    translation = np.asarray(node.translation or [0.0, 0.0, 0.0], dtype=np.float64)
    mesh = gltf.meshes[node.mesh]
    primitive = mesh.primitives[0]
    local = _read_accessor(gltf, blob, primitive.attributes.POSITION).astype(np.float64)
    raw_targets = primitive.targets or []
    names = (mesh.extras or {}).get("targetNames", [str(i) for i in range(len(raw_targets))])
    shapes = [translation + local] + [
        translation + local + _read_accessor(gltf, blob, _position(t)).astype(np.float64)
        for t in raw_targets
    ]
    if frame == "source":
        back = np.linalg.inv(to_gltf)
        shapes = [_apply(back, s) for s in shapes]
    return shapes[0], {str(n): s for n, s in zip(names, shapes[1:], strict=True)}


__all__ = ["MM_TO_M", "MorphTargets", "read_glb_frame", "read_glb_targets", "write_glb"]
