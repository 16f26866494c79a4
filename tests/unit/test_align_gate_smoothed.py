"""The RMSE gate on smoothed (spatially correlated) depth noise: audit finding M8.

A depth camera's depth is smoothed at repair (``repair.depth_smooth_sigma_px``). At 320 x 240 the
smoothing kernel (1.5 px, 3 mm on the skin) is as wide as the template's vertex spacing (about
3 mm), so the noise of neighbouring vertices is correlated (0.78 at under 3 mm, 0.5 at 3-6 mm on
synth04) and the quadric roughness (:func:`scan2morph.align.mesh_noise`) absorbs it: it reads
0.03 mm where each mesh is 0.3 mm off the true surface, while the point-to-plane residual of two
takes still sees the noise. These scenes reproduce that with ground truth: two independent
samplings of one face, their normal noise Gaussian-smoothed over one vertex spacing.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.transform import Rotation

from scan2morph.align import AlignMeshes, rmse_gate, vertex_normals
from tests.unit.test_align import _face

NX, NY = 45, 56  # _face's grid (3.6 mm vertex spacing)


def _smoothed_noise(v, faces, sd_mm: float, sigma_vertices: float, rng) -> np.ndarray:
    """``v`` moved along its normals by Gaussian noise smoothed over ``sigma_vertices`` vertex
    spacings (as a depth camera's smoothed depth samples it), of standard deviation ``sd_mm``."""
    z = ndimage.gaussian_filter(rng.standard_normal((NY, NX)), sigma_vertices).ravel()
    return v + (sd_mm * z / z.std())[:, None] * vertex_normals(v, faces)


def _pair(seed: int):
    """A neutral and a take of one face in one frame (the true pose is the identity), each with
    0.15 mm of normal noise smoothed over one vertex spacing; the ICP region and its centre."""
    v, f = _face(NX, NY)
    rng = np.random.default_rng(seed)
    take, neutral = (_smoothed_noise(v, f, 0.15, 1.0, rng) for _ in range(2))
    upper = np.flatnonzero((v[:, 1] > -15) & (np.hypot(v[:, 0], v[:, 1] + 45) > 40))
    valid = np.ones(len(v), dtype=bool)
    return AlignMeshes(take, valid, neutral, valid, f), upper, v[upper].mean(axis=0)


def _turned(deg: float, centre: np.ndarray) -> np.ndarray:
    """A rotation by ``deg`` degrees about a tilted axis through ``centre`` (4, 4)."""
    t = np.eye(4)
    axis = np.array([1.0, 0.3, 0.0]) / np.hypot(1.0, 0.3)
    t[:3, :3] = Rotation.from_rotvec(np.radians(deg) * axis).as_matrix()
    t[:3, 3] = centre - t[:3, :3] @ centre
    return t


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_quadric_noise_reads_low_on_smoothed_noise(seed):
    # the mechanism of M8, pinned: the true per-mesh noise is 0.15 mm, the quadric reads a
    # quarter of it; the residual of the true pose is what two independent 0.15 mm meshes leave
    meshes, upper, _ = _pair(seed)
    right = rmse_gate(meshes, upper, np.eye(4), source="s01/car")
    assert right.noise_take < 0.06 and right.noise_neutral < 0.06
    assert right.residual_rmse == pytest.approx(np.hypot(0.15, 0.15), rel=0.2)


@pytest.mark.xfail(strict=True, reason="M8: the quadric noise misses smoothed depth noise")
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_right_pose_of_a_smoothed_depth_pair_passes(seed):
    meshes, upper, _ = _pair(seed)
    right = rmse_gate(meshes, upper, np.eye(4), source="s01/car")
    assert right.problem is None, right.problem


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_degree_off_a_smoothed_depth_pair_fails(seed):
    # a fix of M8 must keep this: 1 degree off leaves 0.6 mm (the right pose 0.2 mm)
    meshes, upper, centre = _pair(seed)
    wrong = rmse_gate(meshes, upper, _turned(1.0, centre), source="s01/car")
    assert wrong.residual_rmse > 0.5
    assert wrong.problem is not None
    assert wrong.problem.startswith(f"point-to-plane RMSE {wrong.residual_rmse:.3f} mm")
