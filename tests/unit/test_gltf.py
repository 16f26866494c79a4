"""Tests of scan2morph.io.gltf: glTF 2.0 binary export with morph targets."""

from __future__ import annotations

import json
import struct

import cv2
import numpy as np
import pygltflib
import pytest
import trimesh
from numpy.testing import assert_allclose, assert_array_equal
from pygltflib.validator import validate

from scan2morph.errors import InputError
from scan2morph.geometry import TexturedMesh
from scan2morph.io.gltf import MM_TO_M, MorphTargets, read_glb_frame, read_glb_targets, write_glb

OFFSET = np.array([812.3, -1034.7, 1487.9])  # mm: a face ~1000 mm from the scanner origin


def _face_grid(seed: int = 0, nx: int = 40, ny: int = 50, w: int = 64, h: int = 80):
    """A bumpy 160 x 200 mm grid surface in a scanner frame, with pixel-centre uv, a random
    texture and three smooth 'viseme' targets (absolute positions)."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:ny, 0:nx].astype(np.float64)
    x, y = 4.0 * xs, 4.0 * ys
    z = 30.0 * np.exp(-((x - 80) ** 2 + (y - 100) ** 2) / 3000.0) + rng.normal(0, 0.2, x.shape)
    local = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot *= np.sign(np.linalg.det(rot))
    vertices = local @ rot.T + OFFSET
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    # pixel (px, py) of a w x h image, pixel centres: u = (px + 0.5) / w, v = (py + 0.5) / h
    px = xs.ravel() / (nx - 1) * (w - 1)
    py = ys.ravel() / (ny - 1) * (h - 1)
    uv = np.stack([(px + 0.5) / w, (py + 0.5) / h], axis=1)
    texture = rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    bump = np.exp(-((x - 80) ** 2 + (y - 150) ** 2) / 800.0).reshape(-1, 1)
    targets = {
        name: vertices + bump * rng.normal(scale=8.0, size=3) for name in ("car", "eel", "too")
    }
    return vertices, faces, uv, texture, targets


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    vertices, faces, uv, texture, targets = _face_grid()
    path = tmp_path_factory.mktemp("glb") / "subject.glb"
    write_glb(path, TexturedMesh(vertices, faces, uv, texture), targets)
    return path, vertices, faces, uv, texture, targets


def _accessor(g: pygltflib.GLTF2, index: int) -> np.ndarray:
    """Read an accessor through pygltflib's parse of the file (oracle for our writer)."""
    acc = g.accessors[index]
    view = g.bufferViews[acc.bufferView]
    dtype = {5126: "<f4", 5125: "<u4"}[acc.componentType]
    n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[acc.type]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    data = np.frombuffer(g.binary_blob(), dtype=dtype, count=acc.count * n, offset=start)
    return data.reshape(acc.count, n) if n > 1 else data


def test_targets_are_recovered_to_1e4_mm(written):
    path, vertices, _, _, _, targets = written
    base, read = read_glb_targets(path)
    assert list(read) == ["car", "eel", "too"]
    err_base = np.abs(base - vertices).max()
    err_targets = max(np.abs(read[k] - targets[k]).max() for k in targets)
    assert err_base < 1e-4 and err_targets < 1e-4  # measured: base 4e-6 mm, targets 5e-7 mm
    # Without the node translation float32 of ~1000 mm coordinates would not reach this.
    naive = np.abs(vertices.astype(np.float32).astype(np.float64) - vertices).max()
    assert naive > err_base


def test_structure_with_pygltflib(written):
    path, vertices, faces, uv, texture, targets = written
    g = pygltflib.GLTF2().load_binary(str(path))
    assert g.asset.version == "2.0"
    with pytest.warns(UserWarning, match="provisional"):  # pygltflib's own caveat
        assert validate(g, warning=True) == []  # pygltflib's structural checks
    blob = g.binary_blob()
    assert g.buffers[0].byteLength == len(blob)
    for view in g.bufferViews:
        assert view.byteOffset % 4 == 0
        assert view.byteOffset + view.byteLength <= len(blob)
        assert view.byteStride is None
    with_bounds = 0
    for i, acc in enumerate(g.accessors):
        data = _accessor(g, i)
        size = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[acc.type] * 4
        assert acc.count * size <= g.bufferViews[acc.bufferView].byteLength
        if acc.min:  # min/max equal to the stored data, exactly
            flat = data.reshape(acc.count, -1)
            assert_array_equal(acc.min, flat.min(axis=0))
            assert_array_equal(acc.max, flat.max(axis=0))
            with_bounds += 1
    assert with_bounds == 5  # base POSITION, indices, three target POSITIONs
    (mesh,) = g.meshes
    (prim,) = mesh.primitives
    v = len(vertices)
    assert prim.mode == 4
    for name in ("POSITION", "NORMAL", "TEXCOORD_0"):
        assert g.accessors[getattr(prim.attributes, name)].count == v
    assert len(g.accessors[prim.attributes.POSITION].min) == 3
    assert_array_equal(_accessor(g, prim.indices).reshape(-1, 3), faces)
    assert_array_equal(_accessor(g, prim.attributes.TEXCOORD_0), uv.astype(np.float32))
    normals = _accessor(g, prim.attributes.NORMAL)
    assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
    assert mesh.extras["targetNames"] == ["car", "eel", "too"]
    assert mesh.weights == [0.0, 0.0, 0.0]
    assert len(prim.targets) == 3
    for t in prim.targets:  # pygltflib parses targets as dicts
        pos = g.accessors[t["POSITION"]]
        assert pos.count == v and len(pos.min) == 3 and len(pos.max) == 3
        assert g.accessors[t["NORMAL"]].count == v
    # One node: without a frame, metres in the scanner frame; the face lies ~2 m from the origin,
    # so the node carries the bounding-box centre and the positions are relative to it.
    (node,) = g.nodes
    assert node.mesh == 0 and node.scale is None and node.rotation is None
    centre = MM_TO_M * 0.5 * (vertices.min(0) + vertices.max(0))
    assert_allclose(node.translation, centre, rtol=1e-15)
    assert_allclose(node.extras["source_to_gltf"], np.diag([MM_TO_M] * 3 + [1.0]), rtol=0)
    local = _accessor(g, prim.attributes.POSITION)
    assert np.abs(local).max() < 0.6 * MM_TO_M * np.ptp(vertices, axis=0).max()
    # Texture: embedded PNG, bound as the base color texture, decoding to the same pixels.
    material = g.materials[prim.material]
    assert material.pbrMetallicRoughness.baseColorTexture.index == 0
    assert material.pbrMetallicRoughness.metallicFactor == 0.0
    image = g.images[g.textures[0].source]
    assert image.mimeType == "image/png"
    view = g.bufferViews[image.bufferView]
    png = np.frombuffer(blob[view.byteOffset : view.byteOffset + view.byteLength], np.uint8)
    assert_array_equal(cv2.imdecode(png, cv2.IMREAD_UNCHANGED)[:, :, ::-1], texture)


def test_glb_container_layout(written):
    path = written[0]
    data = path.read_bytes()
    magic, version, total = struct.unpack_from("<III", data, 0)
    assert (magic, version, total) == (0x46546C67, 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A and json_len % 4 == 0
    bin_len, bin_type = struct.unpack_from("<II", data, 20 + json_len)
    assert bin_type == 0x004E4942 and bin_len % 4 == 0
    assert 28 + json_len + bin_len == len(data)
    assert json.loads(data[20 : 20 + json_len])["asset"]["version"] == "2.0"


def test_trimesh_loads_geometry_uv_and_texture(written):
    path, vertices, faces, uv, texture, _ = written
    scene = trimesh.load(path, process=False)
    (geom,) = scene.geometry.values()
    assert_array_equal(geom.faces, faces)
    world = scene.to_geometry()  # applies the node transforms: metres in the scanner frame
    assert_allclose(world.vertices / MM_TO_M, vertices, rtol=0, atol=1e-4)
    # trimesh converts glTF's top-left uv origin to OpenGL's bottom-left one: v -> 1 - v.
    assert_allclose(geom.visual.uv[:, 0], uv[:, 0], atol=1e-7)
    assert_allclose(geom.visual.uv[:, 1], 1.0 - uv[:, 1], atol=1e-7)
    assert_array_equal(np.asarray(geom.visual.material.baseColorTexture), texture)
    # Our normals agree with trimesh's independent vertex normals on this smooth surface.
    g = pygltflib.GLTF2().load_binary(str(path))
    normals = _accessor(g, g.meshes[0].primitives[0].attributes.NORMAL)
    oracle = trimesh.Trimesh(vertices, faces, process=False).vertex_normals
    assert np.min(np.sum(normals * oracle, axis=1)) > np.cos(np.radians(3.0))


def test_target_normals_are_displacements_of_unit_normals(written):
    path, vertices, faces, *_, targets = written
    g = pygltflib.GLTF2().load_binary(str(path))
    prim = g.meshes[0].primitives[0]
    base_n = _accessor(g, prim.attributes.NORMAL)
    for name, t in zip(g.meshes[0].extras["targetNames"], prim.targets, strict=True):
        morphed = base_n + _accessor(g, t["NORMAL"])
        assert_allclose(np.linalg.norm(morphed, axis=1), 1.0, atol=1e-6)
        oracle = trimesh.Trimesh(targets[name], faces, process=False).vertex_normals
        assert np.min(np.sum(morphed * oracle, axis=1)) > np.cos(np.radians(3.0))


def test_minimal_mesh_without_uv_texture_targets_or_metres(tmp_path):
    vertices = np.array([[0.0, 0.0, 1000.0], [10.0, 0.0, 1000.0], [0.0, 10.0, 1000.0]])
    faces = np.array([[0, 1, 2]])
    path = tmp_path / "tri.glb"
    write_glb(path, TexturedMesh(vertices, faces), normals=False, metres=False)
    base, targets = read_glb_targets(path)
    assert targets == {}
    assert_allclose(base, vertices, atol=1e-5)
    g = pygltflib.GLTF2().load_binary(str(path))
    prim = g.meshes[0].primitives[0]
    assert prim.attributes.NORMAL is None and prim.attributes.TEXCOORD_0 is None
    assert prim.targets in (None, []) and len(g.nodes) == 1 and not g.images
    scene = trimesh.load(path, process=False)
    assert_allclose(scene.to_geometry().vertices, vertices, atol=1e-5)


def test_isolated_vertex_gets_a_unit_normal(tmp_path):
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]])
    path = tmp_path / "iso.glb"
    write_glb(path, TexturedMesh(vertices, np.array([[0, 1, 2]])))
    g = pygltflib.GLTF2().load_binary(str(path))
    normals = _accessor(g, g.meshes[0].primitives[0].attributes.NORMAL)
    assert_allclose(normals, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-7)


def test_write_glb_rejects_bad_input(tmp_path):
    vertices, faces, uv, texture, targets = _face_grid(1, nx=5, ny=4, w=8, h=8)
    path = tmp_path / "bad.glb"
    nan = vertices.copy()
    nan[3, 0] = np.nan
    with pytest.raises(InputError, match=r"bad\.glb: vertices: 1 vertices are NaN/inf .*index 3"):
        write_glb(path, TexturedMesh(nan, faces))
    with pytest.raises(InputError, match=r"targets\['eel'\]: 1 vertices are NaN/inf"):
        write_glb(path, TexturedMesh(vertices, faces), targets=dict(targets, eel=nan))
    with pytest.raises(InputError, match=r"targets\['car'\]: expected 20 vertices"):
        write_glb(path, TexturedMesh(vertices, faces), targets=dict(targets, car=vertices[:-1]))
    with pytest.raises(InputError, match=r"vertices: expected a \(V, 3\) array"):
        write_glb(path, TexturedMesh(vertices[:, :2], faces))
    with pytest.raises(InputError, match=r"faces: indices must lie in \[0, 19\], got \[0, 20\]"):
        write_glb(path, TexturedMesh(vertices, np.vstack([faces, [[0, 1, 20]]])))
    with pytest.raises(InputError, match=r"faces: expected integer indices"):
        write_glb(path, TexturedMesh(vertices, faces.astype(float)))
    with pytest.raises(InputError, match=r"faces: expected a non-empty \(F, 3\)"):
        write_glb(path, TexturedMesh(vertices, faces[:, :2]))
    with pytest.raises(InputError, match=r"texture: given without uv"):
        write_glb(path, TexturedMesh(vertices, faces, texture=texture))
    with pytest.raises(InputError, match=r"texture: expected \(H, W, 3\) uint8"):
        write_glb(path, TexturedMesh(vertices, faces, uv, texture.astype(np.float32)))
    with pytest.raises(InputError, match=r"uv: expected finite texture coordinates in \[0, 1\]"):
        write_glb(path, TexturedMesh(vertices, faces, uv * 2.0))
    with pytest.raises(InputError, match=r"uv: expected shape \(20, 2\)"):
        write_glb(path, TexturedMesh(vertices, faces, uv[:-1]))
    assert not path.exists()


def test_read_glb_targets_rejects_non_glb(tmp_path):
    path = tmp_path / "x.glb"
    path.write_bytes(b"not a glb file at all")
    with pytest.raises(InputError, match=r"x\.glb: not a binary glTF file"):
        read_glb_targets(path)


def _similarity(seed: int, origin: np.ndarray) -> np.ndarray:
    """A head-frame-like transform: a proper rotation, mm -> m, ``origin`` to zero."""
    rng = np.random.default_rng(seed)
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot *= np.sign(np.linalg.det(rot))
    out = np.eye(4)
    out[:3, :3] = MM_TO_M * rot
    out[:3, 3] = -MM_TO_M * rot @ origin
    return out


def test_frame_places_the_mesh_and_targets_add(tmp_path):
    vertices, faces, uv, texture, targets = _face_grid(2)
    frame = _similarity(3, vertices.mean(axis=0))
    path = tmp_path / "framed.glb"
    framed = MorphTargets(targets, frame=frame, frame_name="test frame", notes={"car": "a note"})
    write_glb(path, TexturedMesh(vertices, faces, uv, texture), framed)
    assert_array_equal(read_glb_frame(path), frame)
    g = pygltflib.GLTF2().load_binary(str(path))
    (node,) = g.nodes
    assert node.translation is None  # near the origin: no node transform, the file's frame
    assert node.extras["frame"] == g.asset.extras["frame"] == "test frame"
    assert g.meshes[0].extras["targetNotes"] == {"car": "a note"}
    # as a viewer sees it: the frame applied, metres
    base, read = read_glb_targets(path, frame="gltf")
    world = vertices @ frame[:3, :3].T + frame[:3, 3]
    assert_allclose(base, world, rtol=0, atol=1e-8)
    scene = trimesh.load(path, process=False)
    assert_allclose(scene.to_geometry().vertices, world, rtol=0, atol=1e-8)
    # displacements add: base + sum_k w_k (target_k - base) for several weights at once
    w = {"car": 0.7, "eel": -1.0, "too": 2.0}
    shown = base + sum(wk * (read[k] - base) for k, wk in w.items())
    expected = vertices + sum(wk * (targets[k] - vertices) for k, wk in w.items())
    assert_allclose(shown, expected @ frame[:3, :3].T + frame[:3, 3], rtol=0, atol=1e-8)
    # and back in the source frame (mm)
    src_base, src = read_glb_targets(path)
    assert_allclose(src_base, vertices, rtol=0, atol=1e-4)
    assert max(np.abs(src[k] - targets[k]).max() for k in targets) < 1e-4
    # normals are those of the placed mesh (rotated with it)
    prim = g.meshes[0].primitives[0]
    oracle = trimesh.Trimesh(world, faces, process=False).vertex_normals
    normals = _accessor(g, prim.attributes.NORMAL)
    assert np.min(np.sum(normals * oracle, axis=1)) > np.cos(np.radians(3.0))
    # an explicit frame wins over the targets' one
    write_glb(path, TexturedMesh(vertices, faces), framed, frame=np.eye(4))
    assert_array_equal(read_glb_frame(path), np.eye(4))


def test_frame_must_be_a_proper_similarity(tmp_path):
    vertices, faces, *_ = _face_grid(1, nx=5, ny=4, w=8, h=8)
    path = tmp_path / "bad.glb"
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    with pytest.raises(InputError, match=r"frame: expected a rotation times a positive scale"):
        write_glb(path, TexturedMesh(vertices, faces), frame=mirror)
    with pytest.raises(InputError, match=r"frame: expected a rotation times a positive scale"):
        write_glb(path, TexturedMesh(vertices, faces), frame=np.diag([1.0, 2.0, 1.0, 1.0]))
    with pytest.raises(InputError, match=r"frame: expected a finite \(4, 4\)"):
        write_glb(path, TexturedMesh(vertices, faces), frame=np.eye(3))
    with pytest.raises(InputError, match=r"frame: 'head' unknown"):
        read_glb_targets(path, frame="head")
    assert not path.exists()
