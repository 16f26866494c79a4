"""Mesh takes: OBJ (+ MTL + texture), PLY (vertex colours) and GLB rendered through the virtual
camera into a range take, checked against the mesh itself and the synthetic truth."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from numpy.testing import assert_allclose
from PIL import Image

from scan2morph.evaluate.mesh import mesh_accuracy
from scan2morph.evaluate.truth import Truth
from scan2morph.io.mesh_scan import read_landmarks3d, read_mesh_take
from scan2morph.synth.mesh_scan import make_mesh_take, write_landmarks3d, write_mesh_take

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
