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
