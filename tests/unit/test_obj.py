"""OBJ + MTL + PNG export: trimesh as the oracle, upright texture, invalid vertices."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image

from scan2morph.errors import InputError
from scan2morph.io.obj import read_obj, write_obj
from scan2morph.template import build_template, subdivide_template, texture_uv


@pytest.fixture(scope="module")
def face():
    """The level-1 template as a mesh on a tilted plane, with image-convention uv."""
    fine = subdivide_template(build_template(), 1)
    points = np.asarray([320.0, 230.0]) + 70.0 * fine.vertices
    rng = np.random.default_rng(0)
    vertices = np.column_stack([0.7 * points - 200.0, 1000.0 + rng.normal(0, 1, len(points))])
    return vertices, np.asarray(fine.faces), texture_uv(points, 640, 480)


def test_round_trip_with_trimesh(tmp_path, face):
    v, f, uv = face
    tex = np.random.default_rng(1).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    write_obj(tmp_path / "take.obj", v, f, uv=uv, texture=tex)
    mesh = trimesh.load(tmp_path / "take.obj", process=False)
    assert isinstance(mesh, trimesh.Trimesh)
    np.testing.assert_allclose(mesh.vertices, v, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, f)
    np.testing.assert_allclose(mesh.visual.uv, uv * [1, -1] + [0, 1], atol=1e-6)  # v flipped
    np.testing.assert_array_equal(np.asarray(mesh.visual.material.image.convert("RGB")), tex)
    assert "map_Kd take.png" in (tmp_path / "take.mtl").read_text()
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "take.png")), tex)
    back = read_obj(tmp_path / "take.obj")
    np.testing.assert_allclose(back["vertices"], v, atol=1e-6)
    np.testing.assert_allclose(back["uv"], uv, atol=1e-6)
    np.testing.assert_array_equal(back["faces"], f)
    assert back["valid"].all()


def test_texture_opens_upright(tmp_path):
    # top half of the image red, bottom half blue; a vertex at an image row near the top must
    # get red through the OBJ convention (trimesh samples textures as viewers do)
    tex = np.zeros((40, 60, 3), np.uint8)
    tex[:20] = [255, 0, 0]
    tex[20:] = [0, 0, 255]
    points = np.array([[10.0, 5.0], [50.0, 5.0], [10.0, 35.0]])
    uv = texture_uv(points, 60, 40)
    v = np.column_stack([points, np.zeros(3)])
    write_obj(tmp_path / "t.obj", v, [[0, 2, 1]], uv=uv, texture=tex)
    mesh = trimesh.load(tmp_path / "t.obj", process=False)
    colors = trimesh.visual.color.uv_to_color(mesh.visual.uv, mesh.visual.material.image)
    np.testing.assert_array_equal(colors[:, :3], [[255, 0, 0], [255, 0, 0], [0, 0, 255]])


def test_invalid_vertices_keep_their_slot_and_lose_their_faces(tmp_path, face):
    v, f, uv = face
    v = v.copy()
    valid = np.ones(len(v), bool)
    valid[[5, 100, 700]] = False
    v[700] = np.nan  # sampling leaves NaN at invalid vertices
    write_obj(tmp_path / "m.obj", v, f, uv=uv, valid=valid)
    text = (tmp_path / "m.obj").read_text()
    assert "nan" not in text
    back = read_obj(tmp_path / "m.obj")
    assert len(back["vertices"]) == len(v)  # same vertex order across takes
    np.testing.assert_array_equal(back["valid"], valid)
    keep = valid[f].all(axis=1)
    np.testing.assert_array_equal(back["faces"], f[keep])
    np.testing.assert_allclose(back["vertices"][valid], v[valid], atol=1e-6)
    # a NaN vertex is written at the centroid of the finite ones (keeps zoom-to-fit on the face)
    np.testing.assert_allclose(back["vertices"][700], np.delete(v, 700, axis=0).mean(0), atol=1e-5)
    mesh = trimesh.load(tmp_path / "m.obj", process=False)
    # trimesh keeps every vertex in its slot; the unused ones (the invalid vertices) are held by
    # one zero-area marker face each, after the real faces
    assert len(mesh.vertices) == len(v)
    unused = np.setdiff1d(np.arange(len(v)), f[keep].ravel())
    assert len(mesh.faces) == keep.sum() + len(unused)
    np.testing.assert_array_equal(mesh.faces[keep.sum() :], np.repeat(unused[:, None], 3, axis=1))
    # the header counts both kinds of face (the audit's F6: it counted the real ones alone), and
    # says that the listed vertex numbers are OBJ's, from 1 (F2)
    lines = text.splitlines()
    assert lines[0] == (
        f"# scan2morph mesh: {len(v)} vertices (mm), {keep.sum()} faces and {len(unused)} "
        "zero-area faces, one on each vertex no face uses"
    )
    assert sum(x.startswith("f ") for x in lines) == keep.sum() + len(unused)
    assert lines[1].startswith("# vertex numbers below are OBJ's, from 1")
    assert lines[2] == "# invalid: 6 101 701"


def test_bad_input(tmp_path, face):
    v, f, uv = face
    tex = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(InputError, match="m.obj: texture given without uv"):
        write_obj(tmp_path / "m.obj", v, f, texture=tex)
    with pytest.raises(InputError, match=r"m.obj: vertices: expected \(V, 3\)"):
        write_obj(tmp_path / "m.obj", v[:, :2], f)
    with pytest.raises(InputError, match=r"m.obj: faces: index \d+ >= 10 vertices"):
        write_obj(tmp_path / "m.obj", v[:10], f)
    with pytest.raises(InputError, match=r"m.obj: uv: expected \(\d+, 2\)"):
        write_obj(tmp_path / "m.obj", v, f, uv=uv[:-1])
    with pytest.raises(InputError, match=r"m.obj: valid: expected \(\d+,\)"):
        write_obj(tmp_path / "m.obj", v, f, valid=np.ones(3, bool))
    with pytest.raises(InputError, match="nothing.obj: file not found"):
        read_obj(tmp_path / "nothing.obj")
    (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    with pytest.raises(InputError, match="quad.obj: line 5: expected a triangle, got 4"):
        read_obj(tmp_path / "quad.obj")


def test_meshes_of_a_folder_share_one_material(tmp_path, face):
    """The models of a subject share the neutral's texture: one PNG and one MTL for the folder
    (the outputs audit's F7: 56 copies, half of a subject's meshes), each OBJ textured by it in
    trimesh as with a texture of its own."""
    from scan2morph.io.obj import write_material

    v, f, uv = face
    tex = np.random.default_rng(2).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    mtl = write_material(tmp_path, "neutral_texture", tex)
    assert mtl == "neutral_texture.mtl"
    for name in ("a", "b"):
        write_obj(tmp_path / f"{name}.obj", v + len(name), f, uv=uv, texture=mtl)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "a.obj",
        "b.obj",
        "neutral_texture.mtl",
        "neutral_texture.png",
    ]
    mesh = trimesh.load(tmp_path / "b.obj", process=False)
    np.testing.assert_array_equal(np.asarray(mesh.visual.material.image.convert("RGB")), tex)
    np.testing.assert_allclose(mesh.visual.uv, uv * [1, -1] + [0, 1], atol=1e-6)
    with pytest.raises(InputError, match=r"c.obj: texture: no material other.mtl beside the OBJ"):
        write_obj(tmp_path / "c.obj", v, f, uv=uv, texture="other.mtl")
    with pytest.raises(InputError, match="texture given without uv"):
        write_obj(tmp_path / "d.obj", v, f, texture=mtl)
