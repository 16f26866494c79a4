"""Tests of scan2morph.align.point_plane against open3d's point-to-plane ICP (the oracle: one
``registration_icp`` iteration and ``evaluate_registration`` on the same clouds)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from scan2morph.align.point_plane import TRUST_FACTOR, PointToPlane
from scan2morph.open3d_light import open3d


def _clouds(seed: int):
    """A wavy 100 x 80 mm sheet (target, with unit normals) and a noisy, moved sample of it."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(-50, 50, 60), np.linspace(-40, 40, 50))
    z = 8.0 * np.sin(x / 15.0) * np.cos(y / 20.0)
    q = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    gx = 8.0 / 15.0 * np.cos(x / 15.0) * np.cos(y / 20.0)
    gy = -8.0 / 20.0 * np.sin(x / 15.0) * np.sin(y / 20.0)
    n = np.column_stack([-gx.ravel(), -gy.ravel(), np.ones(x.size)])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    pick = rng.choice(len(q), 1200, replace=False)
    p = q[pick] + rng.normal(0.0, 0.2, (1200, 3))
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(rng.normal(0.0, 0.03, 3)).as_matrix()
    pose[:3, 3] = rng.normal(0.0, 1.5, 3)
    return p @ pose[:3, :3].T + pose[:3, 3], q, n


@pytest.mark.parametrize(("kernel", "k"), [("tukey", 2.0), ("huber", 0.5), ("none", 1.0)])
def test_one_step_is_open3ds(kernel, k):
    o3d = open3d()
    reg = o3d.pipelines.registration
    p, q, n = _clouds(3)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(q))
    tgt.normals = o3d.utility.Vector3dVector(n)
    loss = {"tukey": reg.TukeyLoss(k), "huber": reg.HuberLoss(k), "none": reg.L2Loss()}[kernel]
    one = reg.ICPConvergenceCriteria(relative_fitness=0.0, relative_rmse=0.0, max_iteration=1)
    surface = PointToPlane(q, n, 4.0)
    pose = np.eye(4)
    for _ in range(4):  # a few steps from far to near
        want = reg.registration_icp(
            src, tgt, 4.0, pose, reg.TransformationEstimationPointToPlane(loss), one
        )
        got = surface.step(surface.at(p, pose), kernel, k, pose)
        np.testing.assert_allclose(got, np.asarray(want.transformation), rtol=0, atol=1e-9)
        fitness, rmse = surface.at(p, got)[-2:]
        assert fitness == pytest.approx(want.fitness, abs=1e-12)
        assert rmse == pytest.approx(want.inlier_rmse, rel=1e-9)
        pose = got
    assert fitness > 0.95 and rmse < 0.5  # converged onto the sheet


def test_evaluation_without_pairs():
    p, q, n = _clouds(4)
    far = np.eye(4)
    far[:3, 3] = [0.0, 0.0, 500.0]
    assert PointToPlane(q, n, 4.0).at(p, far)[-2:] == (0.0, 0.0)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_step_beyond_the_pairing_distance_is_damped(seed):
    """Skin that slides along itself far from the frame's origin (a nearly flat patch a metre
    away, a scanner's frame) leaves the normal equations nearly singular: from 2 mm off, open3d's
    step (the oracle) throws the source hundreds of mm away and loses every pair; the damped
    step moves no point farther than twice the pairing distance and takes the point-to-plane error
    from 2 mm to the noise's 0.3 mm, nine points in ten or more still paired (the patch slid
    along itself, within the trust region)."""
    o3d = open3d()
    reg = o3d.pipelines.registration
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(-40, 40, 40), np.linspace(-30, 30, 30))
    q = np.column_stack([x.ravel() + 150, y.ravel() - 80, 1000 + 0.05 * rng.normal(size=x.size)])
    n = np.column_stack([1e-4 * rng.normal(size=(x.size, 2)), np.ones(x.size)])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    p = q[rng.choice(len(q), 600, replace=False)] + [0.0, 0.0, 2.0] + rng.normal(0, 0.3, (600, 3))
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(q))
    tgt.normals = o3d.utility.Vector3dVector(n)
    one = reg.ICPConvergenceCriteria(relative_fitness=0.0, relative_rmse=0.0, max_iteration=1)
    plane = reg.TransformationEstimationPointToPlane(reg.L2Loss())
    undamped = np.asarray(
        reg.registration_icp(src, tgt, 10.0, np.eye(4), plane, one).transformation
    )

    def moved(pose):
        return np.linalg.norm(p @ pose[:3, :3].T + pose[:3, 3] - p, axis=1).max()

    surface = PointToPlane(q, n, 10.0)
    got = surface.step(surface.at(p, np.eye(4)), "none", 1.0, np.eye(4))
    assert moved(undamped) > 100.0 and surface.at(p, undamped).fitness == 0.0
    assert moved(got) <= TRUST_FACTOR * 10.0 + 1e-9
    after = surface.at(p, got)
    r = np.einsum("ij,ij->i", after.moved[after.source] - q[after.target], n[after.target])
    assert after.fitness > 0.9 and np.sqrt(np.mean(r**2)) < 0.35  # from 2.0 mm


def test_no_source_points_have_no_pairs():
    """An empty region (every vertex trimmed as moved) has fitness 0, not a division by zero."""
    _, q, n = _clouds(5)
    assert PointToPlane(q, n, 4.0).at(np.zeros((0, 3)), np.eye(4))[-2:] == (0.0, 0.0)
