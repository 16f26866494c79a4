"""Template mesh, thin-plate spline, subdivision, sampling and OBJ export."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
import trimesh
from scipy.interpolate import RBFInterpolator
from scipy.sparse import csgraph, csr_array

from scan2morph.errors import InputError
from scan2morph.io import write_obj
from scan2morph.io.obj import read_obj
from scan2morph.template import (
    TPS,
    FitRules,
    build_template,
    fit_take,
    load_template,
    sample_range,
    save_template,
    subdivide_template,
    texture_uv,
)
from scan2morph.template.mesh import IBUG_CANONICAL, signed_area2


@pytest.fixture(scope="module")
def template():
    return build_template()


def _angles_deg(p, f):
    a, b, c = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]

    def ang(u, v):
        cos = (u * v).sum(1) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1)
        return np.degrees(np.arccos(np.clip(cos, -1, 1)))

    return np.column_stack([ang(b - a, c - a), ang(a - b, c - b), ang(a - c, b - c)])


def test_template_mesh_is_the_papers_size_and_well_formed(template):
    v, f = template.vertices, template.faces
    assert v.shape == (441, 2) and f.shape == (800, 3)
    assert (signed_area2(v, f) < 0).all()  # one orientation, none degenerate
    n = len(v)
    adj = csr_array((np.ones(3 * len(f)), (f.ravel(), np.roll(f, 1, axis=1).ravel())), shape=(n, n))
    assert csgraph.connected_components(adj, directed=False)[0] == 1
    angles = _angles_deg(v, f)
    assert angles.min() > 20.0  # measured 20.7 degrees (at the mouth corners)
    assert np.percentile(angles.min(axis=1), 1) > 30.0  # measured 32.9
    # every fiducial of both sets is a vertex at its canonical iBUG position
    for name in ("closed", "open"):
        numbers, idx = template.fiducials[name]
        np.testing.assert_allclose(v[idx], IBUG_CANONICAL[numbers - 1], atol=1e-12)
    assert len(template.fiducials["closed"][0]) == 20
    # boundary edges: the outer loop and the mouth loop, each edge used by one face only
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(e, axis=0, return_counts=True)
    border = {tuple(x) for x in uniq[count == 1]}
    for loop in (template.boundary, template.mouth_boundary):
        loop_edges = {
            tuple(sorted((int(a), int(b)))) for a, b in zip(loop, np.roll(loop, -1), strict=True)
        }
        assert loop_edges <= border
    assert len(border) == len(template.boundary) + len(template.mouth_boundary)


def test_template_round_trip(tmp_path, template):
    """Read back as written; written again, the same bytes (its zip members carry a fixed time,
    not the time of writing), so that the template's rule running again re-runs no take."""
    save_template(tmp_path / "t.npz", template)
    save_template(tmp_path / "again.npz", build_template())
    assert (tmp_path / "t.npz").read_bytes() == (tmp_path / "again.npz").read_bytes()
    with zipfile.ZipFile(tmp_path / "t.npz") as zf:
        assert {info.date_time for info in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}
    back = load_template(tmp_path / "t.npz")
    np.testing.assert_array_equal(back.faces, template.faces)
    np.testing.assert_array_equal(back.vertices, template.vertices)
    assert back.named == template.named
    for k in template.fiducials:
        np.testing.assert_array_equal(back.fiducials[k][1], template.fiducials[k][1])


def test_tps_matches_scipy_and_interpolates(template):
    rng = np.random.default_rng(0)
    src = IBUG_CANONICAL[template.fiducials["open"][0] - 1]
    dst = 200 + 60 * src + rng.normal(0, 2.0, src.shape)
    spline = TPS.fit(src, dst)
    assert np.abs(spline(src) - dst).max() < 1e-9
    ref = RBFInterpolator(src, dst, kernel="thin_plate_spline")
    pts = rng.uniform(src.min(0) - 0.5, src.max(0) + 0.5, (500, 2))
    np.testing.assert_allclose(spline(pts), ref(pts), atol=1e-6)
    # an affine map is reproduced exactly everywhere (the bending part vanishes)
    a = np.array([[1.3, 0.2], [-0.1, 0.9]])
    aff = TPS.fit(src, src @ a.T + [5.0, -3.0])
    np.testing.assert_allclose(aff(pts), pts @ a.T + [5.0, -3.0], atol=1e-9)
    np.testing.assert_allclose(aff.weights, 0.0, atol=1e-9)


@pytest.mark.parametrize(
    "src, dst, size, match",
    [
        ([[0, 0], [1, 0]], [[0, 0], [1, 0]], None, "at least 3 points"),
        (
            [[0, 0], [1, 0], [0, 0], [0, 1]],
            [[0, 0], [1, 0], [2, 2], [0, 1]],
            None,
            "points 0 and 2 coincide",
        ),
        ([[0, 0], [1, 1], [2, 2], [3, 3]], [[0, 0], [1, 1], [2, 2], [3, 3]], None, "collinear"),
        (
            [[0, 0], [1, 0], [0, np.nan]],
            [[0, 0], [1, 0], [0, 1]],
            None,
            "template point 2 is not finite",
        ),
        (
            [[0, 0], [1, 0], [0, 1]],
            [[0, 0], [1, 0], [0, 500]],
            (100, 100),
            "image point 2 .* outside the 100x100 image",
        ),
    ],
)
def test_tps_bad_input(src, dst, size, match):
    with pytest.raises(InputError, match=match):
        TPS.fit(np.array(src, float), np.array(dst, float), source="s/t", image_size=size)


def test_subdivision_keeps_base_and_splits_edges(template):
    fine = subdivide_template(template, 1)
    f = template.faces
    n_edges = len(
        np.unique(
            np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0
        )
    )
    assert fine.n_vertices == template.n_vertices + n_edges and len(fine.faces) == 4 * len(f)
    np.testing.assert_array_equal(fine.vertices[: template.n_vertices], template.vertices)
    np.testing.assert_allclose(
        signed_area2(fine.vertices, fine.faces).sum(), signed_area2(template.vertices, f).sum()
    )
    assert (signed_area2(fine.vertices, fine.faces) < 0).all()
    assert len(fine.boundary) == 2 * len(template.boundary)
    # midpoints inserted between consecutive loop vertices
    b = fine.boundary
    np.testing.assert_allclose(fine.vertices[b[1]], fine.vertices[[b[0], b[2]]].mean(0))
    two = subdivide_template(template, 2)
    assert len(two.faces) == 16 * len(f)
    assert subdivide_template(template, 0) is template


def test_bilinear_sampling_is_exact_on_a_plane_and_marks_missing_data():
    h, w = 30, 40
    y, x = np.mgrid[0:h, 0:w].astype(float)
    xyz = np.stack([0.5 * x + 10, -0.5 * y, 800 + 0.1 * x - 0.2 * y], axis=-1)
    xyz[10, 10] = np.nan
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, [w - 1, h - 1], (400, 2))
    v, valid = sample_range(xyz, pts)
    near_hole = (np.abs(pts[:, 0] - 10) < 1) & (np.abs(pts[:, 1] - 10) < 1)
    np.testing.assert_array_equal(valid, ~near_hole)
    px, py = pts[valid, 0], pts[valid, 1]
    np.testing.assert_allclose(
        v[valid], np.column_stack([0.5 * px + 10, -0.5 * py, 800 + 0.1 * px - 0.2 * py]), atol=1e-9
    )
    assert np.isnan(v[~valid]).all()
    out, ok = sample_range(xyz, np.array([[-0.5, 3.0], [39.5, 3.0], [5.0, 29.0]]))
    assert ok.tolist() == [False, False, True]
    np.testing.assert_allclose(
        texture_uv(np.array([[0.0, 0.0], [39.0, 29.0]]), w, h),
        [[0.5 / 40, 0.5 / 30], [39.5 / 40, 29.5 / 30]],
    )


@pytest.fixture(scope="module")
def neutral_scan():
    from scan2morph.synth import make_take

    params = dict(width=320, height=240, focal_px=725.0, spike_fraction=0.0, hole_blobs=0)
    return make_take("s1", "neutral", "neutral", "neutral", seed=3, params=params)


def test_fit_take_samples_the_true_surface(template, neutral_scan):
    from scan2morph.evaluate.mesh import mesh_accuracy
    from scan2morph.evaluate.truth import Truth

    s = neutral_scan
    mesh = fit_take(
        template,
        s["truth"]["landmarks2d"],
        s["xyz"],
        (320, 240),
        "closed",
        FitRules(),
        "t1/neutral",
    )
    assert mesh["vertices"].shape == (subdivide_template(template, 1).n_vertices, 3)
    assert mesh["valid"].mean() > 0.8
    truth = Truth.from_arrays(s["truth"])
    acc = mesh_accuracy(mesh["vertices"], mesh["valid"], truth)
    print(acc)
    assert acc["rms_mm"] < 0.3


def test_fit_take_bad_input(template, neutral_scan):
    s = neutral_scan
    lm = s["landmarks"]
    with pytest.raises(InputError, match="landmarks: expected \\(68, 2\\)"):
        fit_take(template, lm[:67], s["xyz"], (320, 240), source="a/b")
    bad = lm.copy()
    bad[30] = np.nan
    with pytest.raises(InputError, match="a/b: landmarks: point 31"):
        fit_take(template, bad, s["xyz"], (320, 240), source="a/b")
    far = lm.copy()
    far[36] = [1000.0, 10.0]
    with pytest.raises(
        InputError, match="a/b: fiducials: image point .* outside the 320x240 image"
    ):
        fit_take(template, far, s["xyz"], (320, 240), source="a/b")
    with pytest.raises(
        InputError, match="a/b: only 0.0% of the template's vertices fall on range data"
    ):
        fit_take(template, lm, np.full_like(s["xyz"], np.nan), (320, 240), source="a/b")
    mirrored = lm.copy()
    mirrored[:, 0] = 319 - mirrored[:, 0]  # landmarks mirrored left-right: the template folds
    with pytest.raises(InputError, match="a/b: landmarks fold the template"):
        fit_take(template, mirrored, s["xyz"], (320, 240), source="a/b")


def test_obj_round_trip_with_trimesh(tmp_path):
    v = np.array([[0, 0, 900], [10, 0, 900], [0, 10, 905], [10, 10, 905.0]])
    f = np.array([[0, 2, 1], [1, 2, 3]])
    uv = np.array([[0.1, 0.2], [0.9, 0.2], [0.1, 0.8], [0.9, 0.8]])
    tex = np.zeros((8, 8, 3), np.uint8)
    tex[:4] = 255  # top half white: image row 0 is the top
    write_obj(tmp_path / "m.obj", v, f, uv=uv, texture=tex)
    mesh = trimesh.load(tmp_path / "m.obj", process=False)
    np.testing.assert_allclose(mesh.vertices, v, atol=1e-6)
    np.testing.assert_allclose(mesh.visual.uv, np.column_stack([uv[:, 0], 1 - uv[:, 1]]), atol=1e-6)
    assert (tmp_path / "m.mtl").read_text().count("map_Kd m.png") == 1
    assert np.asarray(mesh.visual.material.image).shape[:2] == (8, 8)
    # an invalid vertex keeps its slot (same vertex order) but its faces are dropped
    valid = np.array([True, True, True, False])
    write_obj(tmp_path / "n.obj", v, f, valid=valid)
    lines = (tmp_path / "n.obj").read_text().splitlines()
    assert sum(ln.startswith("v ") for ln in lines) == 4
    assert [ln for ln in lines if ln.startswith("f ")] == ["f 1 3 2", "f 4 4 4"]


def test_stable_region_covers_forehead_ridge_and_temples_only(template):
    from scan2morph.template.regions import icp_region, stable_face, upper_face

    fine = subdivide_template(template, 1)
    stable = stable_face(fine)
    named = fine.named
    assert stable[named["forehead_centre"]] and stable[named["nose_mid"]]
    for moving in ("mouth_r", "mouth_l", "chin", "brow_r_inner", "brow_l_inner", "cheekbone_r"):
        assert not stable[named[moving]], moving
    assert 0.1 < stable.mean() < 0.4
    assert not (stable & ~upper_face(fine)).any()  # all of it lies above the nose tip
    np.testing.assert_array_equal(icp_region(fine, "upper_face"), upper_face(fine))
    face = icp_region(fine, "face")  # every vertex: the region align.grow_into may name
    assert face.shape == (len(fine.vertices),) and face.dtype == bool and face.all()
    with pytest.raises(InputError, match="align.icp_region: 'lips' unknown"):
        icp_region(fine, "lips")


def test_obj_opens_in_meshlab_with_every_vertex_in_order(tmp_path, template):
    """MeshLab's own reader (pymeshlab) keeps every template vertex in its slot, invalid ones
    included (their faces are left out), so vertex i is template vertex i there too."""
    import pymeshlab

    fine = subdivide_template(template, 1)
    rng = np.random.default_rng(7)
    v = np.column_stack([fine.vertices * 40.0, 900.0 + rng.normal(0, 1, fine.n_vertices)])
    valid = rng.uniform(size=fine.n_vertices) > 0.05
    uv = rng.uniform(size=(fine.n_vertices, 2))
    write_obj(
        tmp_path / "m.obj", v, fine.faces, uv=uv, texture=np.zeros((4, 4, 3), np.uint8), valid=valid
    )
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(tmp_path / "m.obj"))
    mesh = ms.current_mesh()
    assert mesh.vertex_number() == fine.n_vertices
    np.testing.assert_allclose(mesh.vertex_matrix(), v, atol=1e-5)
    kept = valid[fine.faces].all(axis=1)  # MeshLab drops the degenerate marker faces
    np.testing.assert_array_equal(mesh.face_matrix(), fine.faces[kept])


def test_obj_keeps_every_vertex_in_order_with_uv_in_trimesh(tmp_path, template):
    """trimesh drops the vertices no face references (and splits by texture coordinate): the
    invalid vertices' degenerate faces keep vertex i = template vertex i, with its uv."""
    fine = subdivide_template(template, 1)
    rng = np.random.default_rng(3)
    v = np.column_stack([fine.vertices * 40.0, 900.0 + rng.normal(0, 1, fine.n_vertices)])
    valid = rng.uniform(size=fine.n_vertices) > 0.08
    uv = rng.uniform(size=(fine.n_vertices, 2))
    write_obj(
        tmp_path / "m.obj", v, fine.faces, uv=uv, texture=np.zeros((4, 4, 3), np.uint8), valid=valid
    )
    mesh = trimesh.load(tmp_path / "m.obj", process=False)
    assert len(mesh.vertices) == fine.n_vertices
    np.testing.assert_allclose(mesh.vertices[valid], v[valid], atol=1e-5)
    np.testing.assert_allclose(mesh.visual.uv, np.column_stack([uv[:, 0], 1 - uv[:, 1]]), atol=1e-6)
    back = read_obj(tmp_path / "m.obj")
    np.testing.assert_array_equal(back["valid"], valid)
    np.testing.assert_array_equal(back["faces"], fine.faces[valid[fine.faces].all(axis=1)])
