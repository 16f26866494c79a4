"""glTF 2.0 binary (``.glb``) export of a textured face mesh with named morph targets.

Layout of the written file (one scene, one mesh, one triangle primitive):

- node 0 ``"mm_to_m"``: ``scale = 0.001`` (glTF's unit is the metre; our data are in mm), the
  parent of node 1. Written only when ``metres=True`` (the default).
- node 1 (the mesh node): ``translation = c`` (mm), where c is the centre of the base mesh's
  bounding box. Accessor positions are stored relative to c: float32 of absolute coordinates
  1024-2048 mm from the scanner origin is spaced 1.2e-4 mm, too coarse for the 1e-4 mm round
  trip we promise, while relative to c a face's coordinates (< 200 mm) keep ~1e-5 mm. Target
  displacements are taken from the float32-rounded base, so that base + displacement rounds
  only once (measured: base 4e-6 mm, targets 5e-7 mm for a face 1000-1700 mm away). The
  absolute (scanner-frame) coordinates are ``c + POSITION``; :func:`read_glb_targets` applies c.
- attributes ``POSITION`` (float32, with min/max), ``NORMAL`` (area-weighted vertex normals,
  unit length) and ``TEXCOORD_0`` (float32). glTF's texture coordinates have their origin at the
  top-left corner of the image with v pointing down, which is our image convention
  (u = (x + 0.5) / W, v = (y + 0.5) / H for pixel (x, y)), so uv are written unflipped.
- an embedded PNG texture, bound as ``baseColorTexture`` of a non-metallic double-sided material.
- morph targets: ``POSITION`` displacements (target minus base; each accessor with min/max) and,
  with normals, ``NORMAL`` displacements; their names in ``mesh.extras.targetNames``; default
  ``mesh.weights`` all zero.

Every buffer view starts at a multiple of 4 bytes and every accessor is tightly packed.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Mapping
from os import PathLike
from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import check_vertex_array, face_normals, vertex_normals

_GLB_MAGIC = 0x46546C67  # b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_FLOAT = 5126
_UNSIGNED_INT = 5125
_COMPONENT_DTYPES = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: Scale from our millimetres to glTF's metres, applied by the root node.
MM_TO_M = 1e-3


def _pad4(data: bytearray, fill: bytes) -> None:
    data.extend(fill * (-len(data) % 4))


class _BufferBuilder:
    """Accumulates the BIN chunk, buffer views and accessors of one glTF buffer."""

    def __init__(self):
        self.blob = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        _pad4(self.blob, b"\x00")
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.blob.extend(data)
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, array: np.ndarray, kind: str, target: int, minmax: bool) -> int:
        """Store a float32 (N, c) or uint32 (N,) array; min/max computed from the stored data."""
        component = _UNSIGNED_INT if array.dtype == np.uint32 else _FLOAT
        stored = np.ascontiguousarray(array, dtype="<u4" if component == _UNSIGNED_INT else "<f4")
        acc = {
            "bufferView": self.view(stored.tobytes(), target),
            "componentType": component,
            "count": int(stored.shape[0]),
            "type": kind,
        }
        if minmax:
            flat = stored.reshape(stored.shape[0], -1)
            cast = int if component == _UNSIGNED_INT else float
            acc["min"] = [cast(v) for v in flat.min(axis=0)]
            acc["max"] = [cast(v) for v in flat.max(axis=0)]
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


def write_glb(
    path: str | PathLike[str],
    vertices,
    faces,
    uv=None,
    texture=None,
    targets: Mapping[str, np.ndarray] | None = None,
    normals: bool = True,
    *,
    mesh_name: str = "face",
    metres: bool = True,
) -> None:
    """Write a textured triangle mesh with named morph targets as a glTF 2.0 binary.

    Parameters
    ----------
    path : path-like
        The ``.glb`` file to write (parent directory must exist).
    vertices : (V, 3) float, mm
        Base mesh vertices (e.g. the neutral mesh), no NaN.
    faces : (F, 3) int
        Counter-clockwise triangles (glTF's front faces), indices into ``vertices``.
    uv : (V, 2) float in [0, 1], optional
        Texture coordinates in our image convention (top-left origin, v down), the same as glTF's.
    texture : (H, W, 3) uint8, optional
        RGB texture image, embedded as PNG; requires ``uv``.
    targets : mapping name -> (V, 3) float, mm, optional
        Morph targets as absolute vertex positions in the frame of ``vertices``; stored as
        displacements from the base. Names go to ``mesh.extras.targetNames``.
    normals : bool
        Write area-weighted vertex normals (and their morph-target displacements).
    mesh_name : str
        Name of the mesh and its node.
    metres : bool
        Add a root node scaling mm to m (glTF's unit), so viewers show true size.

    Raises
    ------
    InputError
        On NaN/inf or wrongly shaped vertices or targets (naming the target), faces out of range,
        uv outside [0, 1] or of the wrong shape, a texture that is not (H, W, 3) uint8, or a
        texture without uv.
    """
    source = str(path)
    base = _check_vertices("vertices", vertices, source, None)
    n_vertices = base.shape[0]
    if n_vertices == 0:
        raise InputError(source, "vertices: the mesh has no vertices")
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
    targets = {} if targets is None else dict(targets)
    checked = {
        str(name): _check_vertices(f"targets[{name!r}]", t, source, n_vertices)
        for name, t in targets.items()
    }

    centre = 0.5 * (base.min(axis=0) + base.max(axis=0))
    local32 = (base - centre).astype(np.float32)
    local = local32.astype(np.float64)  # what a reader sees; displacements are taken from it
    buf = _BufferBuilder()
    attributes = {"POSITION": buf.accessor(local32, "VEC3", _ARRAY_BUFFER, minmax=True)}
    base_normals = None
    if normals:
        base_normals = _vertex_normals(base, tri)
        attributes["NORMAL"] = buf.accessor(base_normals, "VEC3", _ARRAY_BUFFER, minmax=False)
    if uv is not None:
        attributes["TEXCOORD_0"] = buf.accessor(uv, "VEC2", _ARRAY_BUFFER, minmax=False)
    indices = buf.accessor(tri.astype(np.uint32).ravel(), "SCALAR", _ELEMENT_ARRAY_BUFFER, True)

    target_list = []
    for t in checked.values():
        entry = {
            "POSITION": buf.accessor(
                ((t - centre) - local).astype(np.float32), "VEC3", _ARRAY_BUFFER, minmax=True
            )
        }
        if normals:
            delta = _vertex_normals(t, tri) - base_normals
            entry["NORMAL"] = buf.accessor(delta, "VEC3", _ARRAY_BUFFER, minmax=False)
        target_list.append(entry)

    primitive = {"attributes": attributes, "indices": indices, "mode": 4, "material": 0}
    pbr = {"metallicFactor": 0.0, "roughnessFactor": 1.0}
    gltf: dict = {
        "asset": {"version": "2.0", "generator": "scan2morph", "extras": {"mesh_units": "mm"}},
        "scene": 0,
    }
    if texture is not None:
        ok, png = cv2.imencode(".png", np.ascontiguousarray(texture[:, :, ::-1]))
        if not ok:  # pragma: no cover - OpenCV fails only on out-of-memory
            raise InputError(source, "texture: PNG encoding failed")
        gltf["images"] = [{"bufferView": buf.view(png.tobytes()), "mimeType": "image/png"}]
        gltf["samplers"] = [{"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071}]
        gltf["textures"] = [{"sampler": 0, "source": 0}]
        pbr["baseColorTexture"] = {"index": 0, "texCoord": 0}
    gltf["materials"] = [
        {"name": f"{mesh_name}_skin", "pbrMetallicRoughness": pbr, "doubleSided": True}
    ]
    if target_list:
        primitive["targets"] = target_list
    mesh = {"name": mesh_name, "primitives": [primitive]}
    if target_list:
        mesh["weights"] = [0.0] * len(target_list)
        mesh["extras"] = {"targetNames": list(checked)}
    gltf["meshes"] = [mesh]
    mesh_node = {"name": mesh_name, "mesh": 0, "translation": [float(c) for c in centre]}
    if metres:
        gltf["nodes"] = [{"name": "mm_to_m", "scale": [MM_TO_M] * 3, "children": [1]}, mesh_node]
    else:
        gltf["nodes"] = [mesh_node]
    gltf["scenes"] = [{"nodes": [0]}]
    gltf["accessors"] = buf.accessors
    gltf["bufferViews"] = buf.views
    _pad4(buf.blob, b"\x00")
    gltf["buffers"] = [{"byteLength": len(buf.blob)}]

    text = bytearray(json.dumps(gltf, separators=(",", ":")).encode("utf-8"))
    _pad4(text, b" ")
    total = 12 + 8 + len(text) + 8 + len(buf.blob)
    with open(path, "wb") as f:
        f.write(struct.pack("<III", _GLB_MAGIC, 2, total))
        f.write(struct.pack("<II", len(text), _CHUNK_JSON) + bytes(text))
        f.write(struct.pack("<II", len(buf.blob), _CHUNK_BIN) + bytes(buf.blob))


def _read_glb(path: Path) -> tuple[dict, bytes]:
    """Parse a GLB container: return its JSON and its BIN chunk."""
    data = path.read_bytes()
    if len(data) < 20 or struct.unpack_from("<I", data, 0)[0] != _GLB_MAGIC:
        raise InputError(path, "not a binary glTF file (missing the 'glTF' magic)")
    version, total = struct.unpack_from("<II", data, 4)
    if version != 2 or total > len(data):
        raise InputError(path, f"header: expected glTF version 2 of {total} bytes, got v{version}")
    gltf, blob, offset = None, b"", 12
    while offset + 8 <= total:
        length, kind = struct.unpack_from("<II", data, offset)
        chunk = data[offset + 8 : offset + 8 + length]
        if kind == _CHUNK_JSON:
            gltf = json.loads(chunk.decode("utf-8"))
        elif kind == _CHUNK_BIN and not blob:
            blob = chunk
        offset += 8 + length
    if gltf is None:
        raise InputError(path, "no JSON chunk")
    return gltf, blob


def _read_accessor(gltf: dict, blob: bytes, index: int) -> np.ndarray:
    """One accessor as an (count, n) or (count,) array of its component type."""
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    dtype = np.dtype(_COMPONENT_DTYPES[acc["componentType"]])
    n = _TYPE_SIZES[acc["type"]]
    offset = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", n * dtype.itemsize)
    arr = np.ndarray(
        (acc["count"], n), dtype, buffer=blob, offset=offset, strides=(stride, dtype.itemsize)
    )
    return arr.copy() if n > 1 else arr[:, 0].copy()


def read_glb_targets(path: str | PathLike[str]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Read back the base mesh and the morph targets written by :func:`write_glb`.

    Parameters
    ----------
    path : path-like
        A ``.glb`` file holding one mesh node whose first primitive carries the targets.

    Returns
    -------
    base : (V, 3) float64, mm
        Base vertex positions in the original frame (the mesh node's translation applied; the
        root mm-to-m scale is not).
    targets : dict name -> (V, 3) float64, mm
        Absolute positions of each morph target (base plus its displacement), in file order.

    Raises
    ------
    InputError
        If the file is not GLB, has no mesh node, or the mesh node is rotated or scaled.
    """
    path = Path(path)
    gltf, blob = _read_glb(path)
    nodes = [n for n in gltf.get("nodes", []) if "mesh" in n]
    if not nodes:
        raise InputError(path, "nodes: no node carries a mesh")
    node = nodes[0]
    if "matrix" in node or node.get("scale", [1, 1, 1]) != [1, 1, 1] or "rotation" in node:
        raise InputError(
            path, f"nodes: mesh node {node.get('name')!r} must carry a translation only"
        )
    translation = np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
    mesh = gltf["meshes"][node["mesh"]]
    primitive = mesh["primitives"][0]
    local = _read_accessor(gltf, blob, primitive["attributes"]["POSITION"]).astype(np.float64)
    raw_targets = primitive.get("targets", [])
    names = mesh.get("extras", {}).get("targetNames", [str(i) for i in range(len(raw_targets))])
    targets = {
        str(name): translation
        + (local + _read_accessor(gltf, blob, t["POSITION"]).astype(np.float64))
        for name, t in zip(names, raw_targets, strict=True)
    }
    return translation + local, targets


__all__ = ["MM_TO_M", "read_glb_targets", "write_glb"]
