"""Synthetic subjects: head mesh, scanner simulation and cohort files against exact truth."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from matplotlib.path import Path as MplPath

from scan2morph.errors import InputError
from scan2morph.io import read_abs, read_color, read_pts
from scan2morph.open3d_light import open3d
from scan2morph.synth import cohort
from scan2morph.synth.head import (
    LABEL_COEFFS,
    SEG_CAVITY,
    articulate,
    build_head,
)
from scan2morph.synth.scanner import (
    BACKGROUND_RGB,
    backproject,
    camera_matrix,
    project,
    surface_normals,
)
from tests.support.configs import repo_config

o3d = open3d()  # open3d without its web viewer, as the library imports it

SMALL = {"width": 160, "height": 120, "focal_px": 362.5}
CLEAN = {"noise_mm": 0.0, "spike_fraction": 0.0, "hole_blobs": 0, "click_noise_px": 0.0}
SEED = 3


def _kind(label: str) -> str:
    return {"neutral": "neutral", "smile": "expression", "sad": "expression"}.get(label, "viseme")


def _take(label: str, subject: str = "s1", take: str | None = None, **params) -> dict:
    return cohort.make_take(subject, label, _kind(label), take or label, SEED, params)


def _head(subject: str = "s1"):
    return build_head(cohort.subject_identity(subject, SEED))


def _posed_mesh(truth: dict) -> tuple[np.ndarray, np.ndarray]:
    pose = truth["pose"]
    return truth["vertices"] @ pose[:3, :3].T + pose[:3, 3], truth["faces"]


def _distance_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32))
    )
    return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def test_default_takes():
    takes = cohort.default_takes()
    assert takes[0] == ("neutral", "neutral", "neutral")
    assert [t for t, k, lab in takes if k == "viseme"] == ["car", "man", "she", "eel", "too"]
    assert ("smile2", "expression", "smile") in takes and ("sad1", "expression", "sad") in takes
    assert len({t for t, _, _ in takes}) == len(takes) == 12
    # the config's default cohort takes exactly these
    config = repo_config()
    assert [(t["take"], t["kind"], t["label"]) for t in config["synthetic"]["takes"]] == takes


def test_camera_convention_round_trip():
    K = camera_matrix(7, 5, 100.0)
    depth = np.full((5, 7), 800.0)
    depth[2, 3] = 650.0
    xyz = backproject(K, depth)
    assert np.allclose(xyz[2, 3], [0.0, 0.0, 650.0])  # (cx, cy) = centre pixel
    uv = project(K, xyz.reshape(-1, 3))
    v, u = np.mgrid[0:5, 0:7]
    assert np.allclose(uv, np.stack([u.ravel(), v.ravel()], 1), atol=1e-9)


def test_surface_normals_of_a_plane():
    K = camera_matrix(40, 30, 300.0)
    # plane n . p = d with n towards the camera
    n = np.array([0.3, -0.2, -1.0])
    n /= np.linalg.norm(n)
    v, u = np.mgrid[0:30, 0:40].astype(float)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    depth = -500.0 / (rays @ n)  # n . (t ray) = -500
    normals = surface_normals(backproject(K, depth))
    assert np.allclose(normals, n, atol=1e-9)


def test_mesh_topology_is_closed_and_shared():
    head = _head()
    assert 20_000 <= len(head.vertices) <= 60_000
    mesh = trimesh.Trimesh(head.vertices, head.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    # the slit: two copies of each mouth-line vertex, equal at rest
    assert len(head.slit_upper) == len(head.slit_lower) > 20
    assert np.array_equal(head.vertices[head.slit_upper], head.vertices[head.slit_lower])
    # the copies belong to different faces: none uses both
    f = head.faces
    up = np.isin(f, head.slit_upper).any(1)
    lo = np.isin(f, head.slit_lower).any(1)
    assert up.sum() > 40 and lo.sum() > 40 and not np.any(up & lo)
    car = articulate(head, LABEL_COEFFS["car"])
    gap = np.linalg.norm(car[head.slit_upper] - car[head.slit_lower], axis=1)
    assert gap.max() > 15.0


def test_xyz_lies_on_the_truth_surface():
    noisy = _take("man", **SMALL, spike_fraction=0.0)
    clean = _take("man", **SMALL, **CLEAN)
    for res, med_max, p99_max in ((clean, 0.01, 0.05), (noisy, 0.3, 0.6)):
        xyz = res["xyz"]
        ok = np.isfinite(xyz[..., 0])
        assert ok.sum() > 2000
        d = _distance_to_mesh(xyz[ok], *_posed_mesh(res["truth"]))
        assert np.median(d) < med_max and np.percentile(d, 99) < p99_max
    # noise is along the ray with the requested sigma
    both = np.isfinite(noisy["xyz"][..., 0]) & np.isfinite(clean["xyz"][..., 0])
    dr = np.linalg.norm(noisy["xyz"][both], axis=1) - np.linalg.norm(clean["xyz"][both], axis=1)
    assert abs(np.std(dr) - 0.1) < 0.01
    # the color image shows the face wherever XYZ has data: hardly any background there
    bg = np.array(BACKGROUND_RGB)
    near_bg = np.all(np.abs(noisy["color"].astype(int) - bg) <= 8, axis=-1)
    assert near_bg.mean() > 0.3 and near_bg[np.isfinite(noisy["xyz"][..., 0])].mean() < 0.01


def test_spikes_and_grazing():
    res = _take("eel", **SMALL, spike_fraction=0.02, spike_mm=30.0)
    xyz = res["xyz"]
    ok = np.isfinite(xyz[..., 0])
    d = _distance_to_mesh(xyz[ok], *_posed_mesh(res["truth"]))
    frac = np.mean(d > 5.0)
    assert 0.01 < frac < 0.03
    # no kept pixel views its surface (normal of the clean image) beyond the grazing limit
    clean = _take("eel", **SMALL, **CLEAN, grazing_deg=60.0)
    xyz = clean["xyz"]
    n = surface_normals(xyz)
    ray = xyz / np.linalg.norm(xyz, axis=-1, keepdims=True)
    cos = -np.sum(n * ray, axis=-1)
    ok = np.isfinite(cos)
    assert np.percentile(cos[ok], 1) > np.cos(np.deg2rad(70.0))


def test_landmarks_project_onto_the_scanned_features():
    res = _take("neutral", **CLEAN)
    truth = res["truth"]
    K, lm2, lm3 = truth["K"], truth["landmarks2d"], truth["landmarks3d"]
    assert np.allclose(project(K, lm3), lm2)
    assert np.array_equal(res["landmarks"], lm2)  # no click noise asked for
    uv = np.rint(lm2).astype(int)
    xyz = res["xyz"][uv[:, 1], uv[:, 0]]
    ok = np.isfinite(xyz[:, 0])
    assert ok.sum() >= 35
    err = np.linalg.norm(xyz[ok] - lm3[ok], axis=1)
    assert np.median(err) < 0.6 and np.percentile(err, 90) < 2.0
    # anatomy: nose tip (31) nearest the camera among the face landmarks of a near-frontal pose
    assert np.argmin(lm3[:, 2]) == 30
    # image order: the subject's right (landmark 1, eye corner 37) on the image left
    assert lm2[0, 0] < lm2[16, 0] and lm2[36, 0] < lm2[45, 0] and lm2[48, 0] < lm2[54, 0]
    # brows above eyes above nose bottom above mouth above chin (image rows grow downwards)
    rows = [lm2[17:27, 1].mean(), lm2[36:48, 1].mean(), lm2[31:36, 1].mean()]
    rows += [lm2[48:68, 1].mean(), lm2[8, 1]]
    assert np.all(np.diff(rows) > 0)


@pytest.mark.parametrize("subject", ["s1", "s2", "s3"])
def test_eye_corners_and_closed_mouth(subject):
    res = _take("neutral", subject=subject, **SMALL)
    lm3 = res["truth"]["landmarks3d"]
    assert 82.0 < np.linalg.norm(lm3[36] - lm3[45]) < 102.0
    assert 40.0 < np.linalg.norm(lm3[48] - lm3[54]) < 62.0
    for a, b in ((61, 67), (62, 66), (63, 65)):
        assert np.linalg.norm(lm3[a] - lm3[b]) < 1e-9
    disp = res["truth"]["displacement"]
    assert not np.any(disp)


def test_open_mouth_has_no_data_inside():
    res = _take("car", **SMALL)
    lm2, lm3 = res["truth"]["landmarks2d"], res["truth"]["landmarks3d"]
    for a, b in ((61, 67), (62, 66), (63, 65)):
        assert np.linalg.norm(lm3[a] - lm3[b]) > 10.0
    inner = MplPath(lm2[60:68])
    v, u = np.mgrid[0:120, 0:160]
    inside = inner.contains_points(np.stack([u.ravel(), v.ravel()], 1)).reshape(120, 160)
    assert inside.sum() > 40
    valid = np.isfinite(res["xyz"][..., 0])
    assert valid[inside].mean() < 0.05
    # it is dark in there, and the truth marks the cavity as not skin
    skin = res["color"][valid].mean()
    assert res["color"][inside].mean() < 0.5 * skin
    head_faces = res["truth"]["skin_faces"]
    assert (~head_faces).sum() > 1000


def test_visemes_move_the_mouth_and_differ():
    head = _head()
    rest = head.vertices
    mouth_c = rest[head.landmarks[[48, 54, 51, 57]]].mean(axis=0)
    region = np.linalg.norm(rest - mouth_c, axis=1) < 35.0
    disp = {
        lab: articulate(head, LABEL_COEFFS[lab])[region] - rest[region]
        for lab in ("car", "man", "she", "eel", "too", "smile", "sad")
    }
    rms = {k: np.sqrt(np.mean(np.sum(d**2, 1))) for k, d in disp.items()}
    assert all(v > 1.5 for v in rms.values()), rms
    labels = sorted(disp)
    for i, a in enumerate(labels):
        for b in labels[i + 1 :]:
            d = np.sqrt(np.mean(np.sum((disp[a] - disp[b]) ** 2, 1)))
            assert d > 1.0, (a, b, d)
    assert np.array_equal(articulate(head, {}), rest)


def test_displacement_and_repeats():
    neutral = _take("neutral", **SMALL)
    s1 = _take("smile", take="smile1", **SMALL)
    s2 = _take("smile", take="smile2", **SMALL)
    for s in (s1, s2):
        assert np.array_equal(s["truth"]["faces"], neutral["truth"]["faces"])
        expect = s["truth"]["vertices"] - neutral["truth"]["vertices"]
        assert np.allclose(s["truth"]["displacement"], expect)
    d1, d2 = s1["truth"]["displacement"], s2["truth"]["displacement"]
    big = np.sqrt(np.mean(np.sum(d1**2, 1)))
    diff = np.sqrt(np.mean(np.sum((d1 - d2) ** 2, 1)))
    assert 0.0 < diff < 0.5 * big
    # poses differ per take, by a few degrees and millimetres
    R1, R2 = s1["truth"]["pose"][:3, :3], s2["truth"]["pose"][:3, :3]
    ang = np.degrees(np.arccos(np.clip((np.trace(R1.T @ R2) - 1) / 2, -1, 1)))
    assert 0.1 < ang < 20.0
    assert np.allclose(R1 @ R1.T, np.eye(3)) and np.isclose(np.linalg.det(R1), 1.0)


def test_determinism_and_files(tmp_path):
    a = _take("she", **SMALL)
    b = _take("she", **SMALL)
    for key in ("xyz", "color", "landmarks"):
        assert np.array_equal(a[key], b[key], equal_nan=True)
    paths = []
    for name, res in (("a", a), ("b", b)):
        p = [tmp_path / f"{name}{ext}" for ext in (".abs", ".png", ".pts", ".npz")]
        cohort.write_take(res, *p)
        paths.append(p)
    for pa, pb in zip(*paths, strict=True):
        assert pa.read_bytes() == pb.read_bytes()
    xyz = read_abs(paths[0][0])
    assert np.allclose(xyz, a["xyz"], atol=1e-6, equal_nan=True)
    assert np.array_equal(read_color(paths[0][1]), a["color"])
    assert np.allclose(read_pts(paths[0][2]), a["landmarks"], atol=1e-3)
    with np.load(paths[0][3]) as z:
        assert set(z.files) == {
            "vertices",
            "faces",
            "skin_faces",
            "pose",
            "K",
            "landmarks3d",
            "landmarks2d",
            "displacement",
        }
        assert z["skin_faces"].dtype == bool and z["faces"].shape[1] == 3
    # another subject is another identity (and another take another pose)
    c = _take("she", subject="s2", **SMALL)
    assert not np.array_equal(c["xyz"], a["xyz"], equal_nan=True)


def test_cavity_segment_is_behind_the_lips():
    head = _head()
    cav = np.unique(head.faces[head.segment == SEG_CAVITY])
    lips_z = head.vertices[head.slit_upper, 2].max()
    assert head.vertices[cav, 2].max() <= lips_z + 1e-9


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"params": {"colour": 1}}, "unknown key"),
        ({"params": {"noise_mm": -1.0}}, "noise_mm"),
        ({"params": {"width": 100.5}}, "width"),
        ({"params": {"grazing_deg": 120.0}}, "grazing_deg"),
        ({"params": {"spike_fraction": "a"}}, "spike_fraction"),
        ({"label": "whistle"}, "label"),
        ({"kind": "expression"}, "kind"),
        ({"subject": "a b"}, "subject"),
        ({"seed": -1}, "seed"),
    ],
)
def test_bad_input_raises(kwargs, match):
    args = {"subject": "s1", "label": "car", "kind": "viseme", "take": "car", "seed": 0}
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        cohort.make_take(**args)


def test_write_take_rejects_incomplete_result(tmp_path):
    with pytest.raises(InputError, match="missing key"):
        cohort.write_take({"xyz": np.zeros((2, 2, 3))}, *(tmp_path / n for n in "abcd"))


def test_expressions_move_the_upper_face_at_realistic_amplitudes():
    """Smile: cheek raise (AU6) and squint; sad: inner-brow raise (AU1) and brow lowering (AU4).
    Visemes and the neutral leave the upper face still."""
    from scan2morph.synth.articulation import FIELDS, LINKED, label_coefficients

    head = _head()
    rest = head.vertices
    disp = {lab: articulate(head, LABEL_COEFFS[lab]) - rest for lab in LABEL_COEFFS}
    lm = rest[head.landmarks]
    # below the lower lids (iBUG 41/42, 47/48), 12 mm down: the infraorbital skin rises 3-6 mm
    for a, b in ((40, 41), (46, 47)):
        below = lm[[a, b]].mean(axis=0) - np.array([0.0, 12.0, 0.0])
        i = np.argmin(np.linalg.norm(rest - below, axis=1))
        assert 3.0 < disp["smile"][i, 1] < 6.0, disp["smile"][i]
    # inner brow ends (iBUG 22, 23) rise, the brows come together; mid-brows (20, 25) drop
    inner, mid = head.landmarks[[21, 22]], head.landmarks[[19, 24]]
    assert (disp["sad"][inner, 1] > 1.5).all(), disp["sad"][inner]
    assert (np.sign(rest[inner, 0]) * disp["sad"][inner, 0] < -1.0).all()
    assert (disp["sad"][mid, 1] < 0.0).all(), disp["sad"][mid]
    brow_fields = [f for fs in LINKED.values() for f in fs]
    assert set(brow_fields) <= set(FIELDS)
    top = np.linalg.norm(np.stack([head.fields[f] for f in brow_fields]), axis=2).max(axis=1)
    assert (top > 1.9).all() and (top < 6.0).all(), top
    # visemes hardly move the brows (only the far fade of the jaw rotation reaches them)
    brows = np.linalg.norm(rest[:, None, :] - lm[None, 17:27], axis=2).min(axis=1) < 10
    for lab in ("car", "man", "she", "eel", "too", "neutral"):
        assert np.abs(disp[lab][brows]).max() < 0.5, lab
    assert np.abs(disp["sad"][brows]).max() > 3.0
    # linked fields follow their driver's intensity (one draw per driver)
    rng = np.random.default_rng(0)
    c = label_coefficients("smile", rng)
    assert c["cheek_raise"] == c["squint"] == c["smile"] != 1.0
    twin = np.random.default_rng(0)
    twin.standard_normal()
    assert rng.bit_generator.state == twin.bit_generator.state


def test_coincident_segments_render_the_same_every_time():
    """Where surfaces of several segments lie at the same depth a pixel shows the segment drawn
    first, the lowest code, in every render: pyrender drew the segments in the order of their
    nodes' memory addresses, so the same take rendered twice could differ in a few pixels (a
    training take differed from run to run). (The segment pass culls back faces: the squares
    face the camera.)"""
    from types import SimpleNamespace

    from scan2morph.synth.scanner import render_colors

    square = np.array(
        [[-20.0, -20.0, 300.0], [20.0, -20.0, 300.0], [20.0, 20.0, 300.0], [-20.0, 20.0, 300.0]]
    )
    n_seg = 5
    vertices = np.concatenate([square] * n_seg)  # one copy of the square per segment, facing
    faces = np.concatenate([np.array([[0, 2, 1], [0, 3, 2]]) + 4 * k for k in range(n_seg)])
    head = SimpleNamespace(faces=faces, segment=np.repeat(np.arange(n_seg), 2))
    colors = np.repeat(np.linspace(0.1, 0.9, n_seg)[:, None], 4, axis=0) * np.ones(3)
    K = camera_matrix(64, 48, 120.0)
    codes = set()
    for k in range(12):
        junk = [object() for _ in range(37 * k)]  # other allocations between the renders
        color, depth, seg = render_colors(head, vertices, colors, K, (64, 48))
        codes |= set(np.unique(seg[24, 32 - 8 : 32 + 8]).tolist())
        assert round(color[24, 32, 0] / 255.0, 2) == pytest.approx(0.1, abs=0.01)
        del junk
    assert codes == {0}
