"""Motion accuracy metrics (``scan2morph.evaluate.motion.motion_accuracy``) against hand values."""

import numpy as np
import pytest

from scan2morph.evaluate.motion import material_accuracy, motion_accuracy


def _case(rng, n=200):
    reference = rng.normal(size=(n, 3))
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # an error with a known normal part (2 mm) and a known tangential part (3 mm) at every vertex
    t = np.cross(normals, rng.normal(size=(n, 3)))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    motion = reference + 2.0 * normals + 3.0 * t
    return reference, normals, motion


def test_error_splits_into_normal_and_tangential_parts():
    rng = np.random.default_rng(7)
    reference, normals, motion = _case(rng)
    suppressed = np.zeros(len(motion), bool)
    suppressed[:20] = True
    motion[:20] = 1e3  # masked vertices do not count
    out = motion_accuracy(motion, motion, reference, reference, suppressed, normals=normals)
    ref_rms = np.sqrt(np.mean(np.sum(reference[20:] ** 2, axis=1)))
    assert out["normal_rms_error_mm"] == pytest.approx(2.0, rel=1e-12)
    assert out["tangential_rms_error_mm"] == pytest.approx(3.0, rel=1e-12)
    assert out["rms_error_mm"] == pytest.approx(np.sqrt(13.0), rel=1e-12)
    assert out["normal_relative_error"] == pytest.approx(2.0 / ref_rms, rel=1e-12)
    assert out["relative_error"] == pytest.approx(np.sqrt(13.0) / ref_rms, rel=1e-12)


def test_vertices_without_normal_are_left_out_of_the_split():
    rng = np.random.default_rng(8)
    reference, normals, motion = _case(rng)
    normals[:50] = np.nan
    motion[:50] += 100.0  # would dominate the split if counted
    out = motion_accuracy(
        motion, motion, reference, reference, np.zeros(len(motion), bool), normals=normals
    )
    assert out["normal_rms_error_mm"] == pytest.approx(2.0, rel=1e-12)
    assert out["tangential_rms_error_mm"] == pytest.approx(3.0, rel=1e-12)


def test_without_normals_there_is_no_split():
    rng = np.random.default_rng(9)
    reference, _, motion = _case(rng)
    out = motion_accuracy(motion, motion, reference, reference, np.zeros(len(motion), bool))
    assert "normal_rms_error_mm" not in out


def test_material_error_leads_and_splits_into_normal_and_sliding_parts():
    """Against the material motion: the same split, and the headline keys come first."""
    rng = np.random.default_rng(10)
    material, normals, motion = _case(rng)
    ideal = motion.copy()  # what the method would give from perfect data: no error there
    suppressed = np.zeros(len(motion), bool)
    out = motion_accuracy(motion, motion, ideal, material, suppressed, normals=normals)
    assert list(out)[:2] == ["material_relative_error", "material_rms_mm"]
    assert out["material_normal_rms_error_mm"] == pytest.approx(2.0, rel=1e-12)
    assert out["material_tangential_rms_error_mm"] == pytest.approx(3.0, rel=1e-12)
    assert out["material_rms_error_mm"] == pytest.approx(np.sqrt(13.0), rel=1e-12)
    ref = np.sqrt(np.mean(np.sum(material**2, axis=1)))
    assert out["material_relative_error"] == pytest.approx(np.sqrt(13.0) / ref, rel=1e-12)
    assert out["relative_error"] == pytest.approx(0.0, abs=1e-12)  # the ideal is met


def test_material_accuracy_of_a_field_counts_only_where_asked():
    rng = np.random.default_rng(11)
    material, normals, motion = _case(rng)
    where = np.ones(len(motion), bool)
    where[:30] = False
    motion[:30] = 1e3
    out = material_accuracy(motion, material, normals, where)
    assert out["material_normal_rms_error_mm"] == pytest.approx(2.0, rel=1e-12)
    assert out["material_tangential_rms_error_mm"] == pytest.approx(3.0, rel=1e-12)


@pytest.mark.parametrize("deg", [1e-4, 0.0316, 1.0, 90.0])
def test_alignment_accuracy_reads_small_angles_exactly(deg):
    """The rotation error of an alignment against a known pose, to 1e-12 of itself also at
    0.0001 degrees (arccos of the trace reads 0.0001 as 0.00010000456)."""
    from scipy.spatial.transform import Rotation

    from scan2morph.evaluate.mesh import alignment_accuracy
    from scan2morph.evaluate.truth import Truth

    def truth(pose):
        z = np.zeros((0, 3))
        return Truth(z, np.zeros((0, 3), int), np.zeros(0, bool), pose, np.eye(3), z, z, z, {})

    neutral, take = np.eye(4), np.eye(4)
    take[:3, 3] = [5.0, -3.0, 600.0]
    err = np.eye(4)
    axis = np.array([0.3, 0.5, 0.81]) / np.linalg.norm([0.3, 0.5, 0.81])
    err[:3, :3] = Rotation.from_rotvec(np.radians(deg) * axis).as_matrix()
    estimate = err @ neutral @ np.linalg.inv(take)  # off the true transform by err
    vertices = np.array([[0.0, 0.0, 600.0], [10.0, 0.0, 600.0], [0.0, 10.0, 610.0]])
    acc = alignment_accuracy(estimate, vertices, np.ones(3, bool), truth(take), truth(neutral))
    assert acc["rotation_deg"] == pytest.approx(deg, rel=1e-12)


def _sheet(xs, ys, offset):
    """A grid sheet of the head frame's z = 0 plane: vertices and triangles (indices + offset)."""
    x, y = np.meshgrid(xs, ys)
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    i = np.arange(x.size).reshape(x.shape) + offset
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def test_a_vertex_on_the_closed_mouth_follows_its_own_lip():
    """Two lips meet along a slit at rest (two copies of its vertices, as the synthetic head has)
    and part in the take: the lower lip drops 10 mm. A neutral vertex on the slit is as close
    to either lip; with the template's lip sides it takes its own lip's motion, and vertices off
    the slit are unaffected."""
    from scipy.spatial.transform import Rotation

    from scan2morph.errors import InputError
    from scan2morph.evaluate.motion import true_motion
    from scan2morph.evaluate.truth import Truth

    xs = np.arange(-25.0, 25.1, 5.0)
    upper, fu = _sheet(xs, np.arange(0.0, 10.1, 2.5), 0)  # head frame: y up
    lower, fl = _sheet(xs, np.arange(-10.0, 0.1, 2.5), len(upper))
    rest = np.vstack([upper, lower])
    faces = np.vstack([fu, fl])
    moved = rest + np.where(np.arange(len(rest))[:, None] < len(upper), [0, 0.5, 0], [0, -10, 0])
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("xyz", [12, -20, 7], degrees=True).as_matrix()
    pose[:3, 3] = [3.0, -40.0, 650.0]
    posed = lambda p: p @ pose[:3, :3].T + pose[:3, 3]  # noqa: E731
    lm = np.zeros((68, 3))
    # iBUG 61-68: corner, upper lip left to right, corner, lower lip right to left
    lm[60:68] = posed(
        np.array([[-20, 0, 0], [-10, 0, 0], [0, 0, 0], [10, 0, 0], [20, 0, 0]] + [[10, 0, 0]])[
            [0, 1, 2, 3, 4, 5, 2, 1]
        ]
    )

    def truth(v):
        skin = np.ones(len(faces), dtype=bool)
        z = np.zeros((68, 2))
        return Truth(v, faces, skin, pose, np.full((3, 3), np.nan), lm, z, v - rest, {})

    query = posed(np.array([[-5.0, 0, 0], [4.0, 0, 0], [6.0, 0, 0], [0, 4.0, 0], [0, -4.0, 0]]))
    sides = np.array([1, 1, -1, 0, 0])  # lower, lower, upper lip; two vertices off the slit
    got = true_motion(query, truth(rest), truth(moved), sides)
    rot = pose[:3, :3]
    want = np.array([[0, -10, 0], [0, -10, 0], [0, 0.5, 0], [0, 0.5, 0], [0, -10, 0]]) @ rot.T
    np.testing.assert_allclose(got, want, atol=1e-4)
    with pytest.raises(InputError, match=r"sides: expected \(5,\) lip sides"):
        true_motion(query, truth(rest), truth(moved), sides[:4])
    # without sides a slit vertex takes either lip's motion: the coin the sides decide
    blind = true_motion(query, truth(rest), truth(moved))
    assert all(
        np.allclose(b, w0, atol=1e-4) or np.allclose(b, w1, atol=1e-4)
        for b, w0, w1 in zip(
            blind[:3], [[0, -10, 0] @ rot.T] * 3, [[0, 0.5, 0] @ rot.T] * 3, strict=True
        )
    )


def test_template_lip_sides():
    """The template's upper inner-lip contour is the upper lip (-1), the lower one the lower
    lip (+1); the corners, the cheeks and the chin are neither."""
    from scan2morph.evaluate.motion import template_lip_sides
    from scan2morph.template.mesh import IBUG_CANONICAL

    lips = IBUG_CANONICAL[60:68]
    points = np.vstack([lips[1:4], lips[5:8], lips[[0, 4]], [[1.5, 1.7], [0.0, 2.6]]])
    np.testing.assert_array_equal(template_lip_sides(points), [-1, -1, -1, 1, 1, 1, 0, 0, 0, 0])
