"""Mesh takes: OBJ (+ MTL + texture), PLY (vertex colours) and GLB rendered through the virtual
camera into a range take, checked against the mesh itself and the synthetic truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from numpy.testing import assert_allclose
from PIL import Image

from scan2morph.evaluate.mesh import mesh_accuracy
from scan2morph.evaluate.truth import Truth
from scan2morph.io.mesh_scan import read_landmarks3d, read_mesh_take
from scan2morph.io.uv_orientation import MIN_GAIN, texture_agreement
from scan2morph.synth.mesh_scan import make_mesh_take, write_landmarks3d, write_mesh_take
from tests.support.real_head import COLOR_MAP, GLB

#: A tiny virtual camera.
TINY_CAMERA = dict(width=160, height=120)


@pytest.fixture(scope="module")
def scan():
    """A synthetic mesh scan (the same identity as the bad-input tests' takes)."""
    return make_mesh_take("s1", "neutral", "neutral", "neutral", seed=3)


@pytest.fixture(scope="module")
def textured(scan, tmp_path_factory):
    """The scan as OBJ + MTL + texture and as GLB, with a planar UV map whose texture is a
    colour ramp: the texel of a surface point is known from its position."""
    d = tmp_path_factory.mktemp("textured")
    v = scan["vertices"]
    lo, hi = v.min(axis=0), v.max(axis=0)
    uv = (v[:, :2] - lo[:2]) / (hi[:2] - lo[:2])
    ramp = np.zeros((256, 256, 3), np.uint8)
    ramp[..., 0] = np.arange(256)[None, :]  # red grows with u
    ramp[..., 1] = np.arange(256)[::-1, None]  # green grows with v (image rows run down)
    ramp[..., 2] = 90
    visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(ramp))
    mesh = trimesh.Trimesh(v, scan["faces"], visual=visual, process=False)
    mesh.export(d / "face.obj")
    mesh.export(d / "face.glb")
    write_landmarks3d(d / "face.txt", scan["landmarks"])
    return d, lo, hi


def test_ply_scan_renders_onto_the_true_surface(scan, tmp_path):
    files = (tmp_path / "s.ply", tmp_path / "s.txt", tmp_path / "t.npz")
    write_mesh_take(scan, *files)
    take = read_mesh_take(files[0], None, files[1], TINY_CAMERA)
    ok = np.isfinite(take.xyz).all(axis=-1)
    acc = mesh_accuracy(take.xyz[ok], np.ones(ok.sum(), bool), Truth.from_arrays(scan["truth"]))
    print(f"\nmesh scan pixels against the true surface: {acc}")
    assert acc["rms_mm"] < 0.2  # the scan's 0.1 mm vertex noise
    assert take.report["colour"] == "vertex colours"
    # the projected landmarks lie where the rendered surface holds their 3D points (within a
    # pixel, 1.3 mm here, and the 0.4 mm click noise off the surface)
    numbers = np.array([31, 37, 46, 49, 55]) - 1  # not the inner eye corners: steep there
    u, v = np.rint(take.landmarks[numbers]).astype(int).T
    ref = read_landmarks3d(files[1])[numbers]
    assert np.linalg.norm(take.xyz[v, u] - ref, axis=1).max() < 2.5
    # the camera the store records maps the take's frame to the pixels
    cam = take.xyz[ok] @ take.pose[:3, :3].T + take.pose[:3, 3]
    pix = cam[:, :2] / cam[:, 2:] * np.diag(take.K)[:2] + take.K[:2, 2]
    v, u = np.nonzero(ok)
    assert_allclose(pix, np.column_stack([u, v]), atol=1e-3)


@pytest.mark.parametrize("name", ["face.obj", "face.glb"])
def test_texture_lands_on_its_surface_point(textured, name):
    """Each rendered pixel shows the texel of the surface point its XYZ says it sees."""
    d, lo, hi = textured
    take = read_mesh_take(d / name, None, d / "face.txt", TINY_CAMERA)
    assert take.report["colour"] == "texture"
    ok = np.isfinite(take.xyz).all(axis=-1)
    uv = (take.xyz[ok][:, :2] - lo[:2]) / (hi[:2] - lo[:2])
    expected = np.column_stack([uv[:, 0] * 255, uv[:, 1] * 255])
    got = take.color[ok][:, :2].astype(float)
    err = np.abs(got - expected)
    print(f"\n{name}: texel error median {np.median(err):.2f}, p95 {np.percentile(err, 95):.2f}")
    assert np.median(err) < 2.0 and np.percentile(err, 95) < 6.0


def test_texture_column_supplies_a_missing_texture(textured, tmp_path):
    d, _, _ = textured
    (tmp_path / "face.obj").write_text((d / "face.obj").read_text())  # no MTL beside it
    png = next(d.glob("*.png"))
    take = read_mesh_take(tmp_path / "face.obj", png, d / "face.txt", TINY_CAMERA)
    assert take.report["colour"] == "texture"
    assert take.color[60, 80].tolist() != [44, 46, 56]  # the face, not the background
    # a ramp has no features: it agrees with the surface neither way up and is kept as read
    assert take.report["uv_flipped"] is False


@pytest.fixture(scope="module")
def baked(scan, tmp_path_factory):
    """The scan as a GLB without a texture of its own, and its vertex colours (the albedo with
    brows, lids and lips under the scanner's lamp) baked into a PNG through a cylindrical UV
    map; once with the glTF's UVs as glTF has them, once written OBJ-style (v = 0 at the image
    bottom), as a converted file can have them."""
    from scipy.spatial import cKDTree

    d = tmp_path_factory.mktemp("baked")
    v = scan["vertices"]
    centre = v.mean(axis=0)
    u = np.arctan2(v[:, 0] - centre[0], v[:, 2] - centre[2]) / (2 * np.pi) + 0.5
    uv = np.column_stack([u, (v[:, 1] - v[:, 1].min()) / np.ptp(v[:, 1])])  # v = 0 at the chin
    n = 512
    texel = (np.arange(n) + 0.5) / n
    tu, tv = np.meshgrid(texel, 1.0 - texel)  # image rows run down: row 0 at v = 1
    _, nearest = cKDTree(uv).query(np.column_stack([tu.ravel(), tv.ravel()]))
    Image.fromarray(scan["colors"][nearest].reshape(n, n, 3)).save(d / "skin.png")
    for name, uv_file in (("right.glb", uv), ("obj_style.glb", uv * [1, -1] + [0, 1])):
        material = trimesh.visual.material.PBRMaterial()
        visual = trimesh.visual.TextureVisuals(uv=uv_file, material=material)
        trimesh.Trimesh(v, scan["faces"], visual=visual, process=False).export(d / name)
    write_landmarks3d(d / "face.txt", scan["landmarks"])
    return d


def test_a_sheet_texture_upside_down_on_the_mesh_is_turned_the_right_way(baked):
    """The same texture from the sheet on the same surface: on the GLB whose UVs are glTF's it
    is kept as read; on the one whose UVs were written OBJ-style it is flipped, and the take's
    colour image is the first one's. Known answer: only one reading puts the baked brows, lids
    and lips on the surface that has them."""
    camera = dict(width=320, height=240)
    right = read_mesh_take(baked / "right.glb", baked / "skin.png", baked / "face.txt", camera)
    wrong = read_mesh_take(baked / "obj_style.glb", baked / "skin.png", baked / "face.txt", camera)
    print(
        f"\nagreement as read / flipped: {right.report['uv_agreement']}, "
        f"{wrong.report['uv_agreement']}"
    )
    assert right.report["uv_flipped"] is False and wrong.report["uv_flipped"] is True
    assert right.report["uv_agreement"][0] > right.report["uv_agreement"][1] + MIN_GAIN
    # the same two renders (up to the UVs' float32 rounding in the files)
    flipped_back = wrong.report["uv_agreement"][::-1]
    np.testing.assert_allclose(flipped_back, right.report["uv_agreement"], atol=1e-3)
    diff = np.abs(wrong.color.astype(int) - right.color.astype(int))
    assert np.mean(diff) < 0.05 and np.percentile(diff, 99.9) <= 2
    # the file's own texture is never second-guessed: no check without a sheet texture (with
    # the landmark file, whose camera is found without the surface search)
    own = read_mesh_take(baked / "right.glb", None, baked / "face.txt", camera)
    assert "uv_flipped" not in own.report


@pytest.mark.realdata
@pytest.mark.skipif(not GLB.is_file(), reason=f"real head scan absent: {GLB}")
def test_the_real_heads_colour_map_is_turned_the_way_it_lies_on_the_scan():
    """The real head's glTF carries OBJ-style UVs (the real-data tests flip its v to show the
    colour map; three.js's own example of it loads the map with flipY): given the colour map in
    the sheet's texture column, the take turns it, by a clear margin (measured at 320 x 240:
    0.01 as read, 0.24 flipped; at 640 x 480 -0.01 and 0.20)."""
    take = read_mesh_take(GLB, COLOR_MAP, None, dict(width=320, height=240), 41.4)
    as_read, flipped = take.report["uv_agreement"]
    print(f"\nreal head: agreement {as_read:.3f} as read, {flipped:.3f} flipped")
    assert take.report["uv_flipped"] is True
    assert flipped > 0.12 and as_read < 0.05


def test_agreement_needs_a_surface():
    """Fewer than 100 face pixels: no measure (NaN), and a flat colour has no edges to agree."""
    xyz = np.full((40, 40, 3), np.nan)
    assert np.isnan(texture_agreement(np.zeros((40, 40, 3), np.uint8), xyz))
    yy, xx = np.mgrid[0:40, 0:40].astype(float)
    dome = np.dstack([xx, yy, 200.0 + 0.05 * ((xx - 20) ** 2 + (yy - 20) ** 2)])
    assert np.isnan(texture_agreement(np.full((40, 40, 3), 128, np.uint8), dome))


def _colour_ratio(flat: dict, textured: dict) -> tuple[np.ndarray, np.ndarray]:
    """Textured over flat red of each vertex, and where both are far from 0 and 255 (uint8
    rounding and clipping would spoil the ratio; the lit skin's red is its brightest)."""
    a = flat["colors"][:, 0].astype(float)
    b = textured["colors"][:, 0].astype(float)
    ok = (a > 60) & (b > 20) & (b < 250)
    return b / np.maximum(a, 1.0), ok


def test_skin_texture_is_fixed_to_the_skin(scan):
    """With ``skin_texture`` the vertex colours carry the skin's detail: the factor of a vertex
    (textured over flat colour: the lamp's shading cancels) is the same in every take however
    the face moves and its shading changes, the geometry and clicks are those of the flat scan,
    and 0 gives the flat albedo."""
    textured = make_mesh_take("s1", "neutral", "neutral", "neutral", 3, {"skin_texture": 1.0})
    flat0 = make_mesh_take("s1", "neutral", "neutral", "neutral", 3, {"skin_texture": 0.0})
    assert np.array_equal(flat0["colors"], scan["colors"])
    for key in ("vertices", "faces", "landmarks"):
        assert np.array_equal(textured[key], scan[key])
    smile = make_mesh_take("s1", "smile", "expression", "smile1", 3)
    smile_tex = make_mesh_take("s1", "smile", "expression", "smile1", 3, {"skin_texture": 1.0})
    r_neutral, ok_n = _colour_ratio(scan, textured)
    r_smile, ok_s = _colour_ratio(smile, smile_tex)
    ok = ok_n & ok_s
    assert ok.sum() > 5000  # the lit face
    # the shading differs between the takes (the smile turns the cheeks' normals) ...
    shading = smile["colors"][ok, 0].astype(float) / scan["colors"][ok, 0].astype(float)
    moved = np.abs(shading - 1.0) > 0.05
    assert moved.sum() > 200
    # ... the skin's detail does not: the same factor to the uint8 rounding (0.5 / 60 ~ 1 %)
    diff = np.abs(r_smile[ok] - r_neutral[ok])[moved]
    print(
        f"\n{moved.sum()} vertices shaded otherwise; skin detail factor: neutral vs smile median {np.median(diff):.4f}, p99 "
        f"{np.percentile(diff, 99):.4f}; |factor - 1| median "
        f"{np.median(np.abs(r_neutral[ok] - 1)):.3f}"
    )
    assert np.median(diff) < 0.008 and np.percentile(diff, 99) < 0.03
    # and there is detail to correlate: freckles and mottling of a few per cent and more
    assert np.median(np.abs(r_neutral[ok] - 1.0)) > 0.02
    assert np.percentile(r_neutral[ok], 1) < 0.9  # freckles: red down by up to 27 %


def test_a_meshs_companion_files_are_the_ones_its_reader_reads(textured, tmp_path):
    """An OBJ's MTL and texture (a comment naming another MTL is not read), a glTF's external
    buffer and image (not its data: URI), none for a GLB: each changes the take's checksum."""
    from scan2morph.io.mesh_file import companion_files
    from scan2morph.stages.check import input_checksums

    d, _, _ = textured
    obj = d / "face.obj"
    (mtl,) = d.glob("*.mtl")
    (png,) = d.glob("*.png")
    assert companion_files(obj) == [mtl, png]
    assert companion_files(d / "face.glb") == [] and companion_files(d / "absent.obj") == []
    commented = tmp_path / "commented.obj"
    commented.write_bytes(b"# mtllib other.mtl\n" + obj.read_bytes())
    (tmp_path / "other.mtl").write_text("newmtl x\n")
    assert companion_files(commented) == []  # its own mtllib names a file not beside it
    # a bounded scan (the workflow's, each time it builds its jobs) reads the head only: an
    # mtllib line beyond it, and a larger glTF, give none; a PLY or GLB is not read at all
    copy = tmp_path / "copy"
    copy.mkdir()
    for f in (obj, mtl, png):
        copy.joinpath(f.name).write_bytes(f.read_bytes())
    late = copy / "late.obj"
    late.write_bytes(b"# a long header\n" * 100 + obj.read_bytes())  # mtllib after 1600 bytes
    assert companion_files(late) == [copy / mtl.name, copy / png.name]
    assert companion_files(late, max_bytes=1000) == []
    assert companion_files(obj, max_bytes=1000) == [mtl, png]
    gltf = tmp_path / "face.gltf"
    (tmp_path / "mesh data.bin").write_bytes(b"\0" * 8)
    (tmp_path / "skin.png").write_bytes(png.read_bytes())
    doc = {
        "buffers": [
            {"uri": "mesh%20data.bin"},
            {"uri": "data:application/octet-stream;base64,AA=="},
        ],
        "images": [{"uri": "skin.png"}, {"uri": "absent.png"}],
    }
    gltf.write_text(json.dumps(doc))
    assert companion_files(gltf) == [tmp_path / "mesh data.bin", tmp_path / "skin.png"]
    assert companion_files(gltf, max_bytes=10) == []
    before = input_checksums({"mesh": str(obj)})
    assert input_checksums({"mesh": str(d / "face.glb")})["mesh"] != before["mesh"]
    assert input_checksums({"mesh": str(copy / obj.name)}) == before  # content, not place
    image = np.asarray(Image.open(copy / png.name)).copy()
    image[0, 0] = 255 - image[0, 0]
    Image.fromarray(image).save(copy / png.name)
    assert input_checksums({"mesh": str(copy / obj.name)}) != before
