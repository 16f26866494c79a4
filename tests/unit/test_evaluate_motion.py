"""Motion accuracy metrics (``scan2morph.evaluate.motion.motion_accuracy``) against hand values."""

import numpy as np
import pytest

from scan2morph.evaluate.motion import material_accuracy, motion_accuracy
from tests.support.meshes import grid_mesh


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


def _lips(slit, nx=41, rows=9, spacing=1.25):
    """Two lip sheets of the head frame's z = 0 plane (y up) meeting along the slit
    ``y = slit(x)``, x in [-25, 25] mm: each lip has its own copy of the slit's vertices, as the
    synthetic head has. Returns the vertices, the triangles and which vertices are the lower
    lip's."""
    flat, tri = grid_mesh(nx, rows, spacing)
    x = flat[:, 0] - 25.0
    out, faces = [], []
    for sign in (1.0, -1.0):  # upper lip, then lower lip
        out.append(np.column_stack([x, slit(x) + sign * flat[:, 1] / spacing, np.zeros(len(x))]))
        faces.append(tri + (len(flat) if sign < 0 else 0))
    lower = np.arange(2 * len(flat)) >= len(flat)
    return np.vstack(out), np.vstack(faces), lower


def test_a_vertex_on_the_closed_mouth_follows_its_own_lip():
    """Two lips meet along a wavy slit at rest (two copies of its vertices) and part in the take:
    the lower lip drops 10 mm. A neutral vertex on the slit is as close to either lip; with the
    template's lip sides it takes its own lip's motion, also where the slit is 1.5 mm off the
    straight line through the inner-lip landmarks, and vertices off the slit are unaffected.
    ``true_positions`` puts the same skin points in a take of another pose."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    from scan2morph.errors import InputError
    from scan2morph.evaluate.motion import true_motion, true_positions
    from scan2morph.evaluate.truth import Truth

    def slit(x):  # through the landmarks at x = 0, +-10, +-20 and 1.5 mm off between them
        return 1.5 * np.sin(np.pi * x / 10.0)

    rest, faces, lower = _lips(slit)
    moved = rest + np.where(lower[:, None], [0, -10, 0], [0, 0.5, 0])
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("xyz", [12, -20, 7], degrees=True).as_matrix()
    pose[:3, 3] = [3.0, -40.0, 650.0]
    posed = lambda p: p @ pose[:3, :3].T + pose[:3, 3]  # noqa: E731
    lm = np.zeros((68, 3))
    # iBUG 61-68: corner, upper lip left to right, corner, lower lip right to left
    xs = np.array([-20, -10, 0, 10, 20, 10, 0, -10], dtype=float)
    lm[60:68] = posed(np.column_stack([xs, slit(xs), np.zeros(8)]))

    def truth(v):
        skin = np.ones(len(faces), dtype=bool)
        z = np.zeros((68, 2))
        return Truth(v, faces, skin, pose, np.full((3, 3), np.nan), lm, z, v - rest, {})

    # on the slit where it bulges up (x = 5, -15) and down (x = -5, 15), and off it
    qx = np.array([5.0, -15.0, -5.0, 15.0, 5.0, 0.0, 0.0])
    qy = slit(qx) + np.array([0, 0, 0, 0, 0, 4.0, -4.0])
    query = posed(np.column_stack([qx, qy, np.zeros(7)]))
    # where the slit bulges up, the lower lip's first faces lie above the landmarks' line, and
    # where it sags, the upper lip's lie below it: an upper vertex at a bulge and a lower one at
    # a sag are where a side taken from that line matches the other lip
    sides = np.array([-1, -1, 1, 1, 1, 0, 0])  # the lip each vertex is on; two off the slit
    got = true_motion(query, truth(rest), truth(moved), sides)
    rot = pose[:3, :3]
    down, still = np.array([0, -10.0, 0]) @ rot.T, np.array([0, 0.5, 0]) @ rot.T
    want = np.array([still, still, down, down, down, still, down])
    np.testing.assert_allclose(got, want, atol=1e-4)
    with pytest.raises(InputError, match=r"sides: expected \(7,\) lip sides"):
        true_motion(query, truth(rest), truth(moved), sides[:4])
    # without sides a slit vertex takes either lip's motion: the coin the sides decide
    blind = true_motion(query, truth(rest), truth(moved))
    assert all(np.allclose(b, down) or np.allclose(b, still) for b in blind[:5])
    # the same skin points in the take, in the take's own frame (another pose): the oracle of a
    # correspondence
    other = np.eye(4)
    other[:3, :3] = Rotation.from_euler("xyz", [-5, 30, 2], degrees=True).as_matrix()
    other[:3, 3] = [-20.0, 10.0, 700.0]
    take = replace(truth(moved), pose=other)
    head = (query - pose[:3, 3]) @ rot + want @ rot  # the skin points in the head frame, moved
    got = true_positions(query, truth(rest), {"t": take}, sides)["t"]
    np.testing.assert_allclose(got, head @ other[:3, :3].T + other[:3, 3], atol=1e-4)


def test_template_lip_sides():
    """The template's upper inner-lip contour is the upper lip (-1), the lower one the lower
    lip (+1); the corners, the cheeks and the chin are neither."""
    from scan2morph.evaluate.motion import template_lip_sides
    from scan2morph.template.mesh import IBUG_CANONICAL

    lips = IBUG_CANONICAL[60:68]
    points = np.vstack([lips[1:4], lips[5:8], lips[[0, 4]], [[1.5, 1.7], [0.0, 2.6]]])
    np.testing.assert_array_equal(template_lip_sides(points), [-1, -1, -1, 1, 1, 1, 0, 0, 0, 0])
