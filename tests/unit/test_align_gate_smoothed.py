"""The RMSE gate on smoothed (spatially correlated) depth noise: the zero-click audit's M8.

A depth camera's depth is smoothed at repair (``repair.depth_smooth_sigma_px``). At 320 x 240 the
smoothing kernel (1.5 px, 3 mm on the skin) is as wide as the template's vertex spacing (1.6 px),
so the noise of neighbouring vertices is correlated and the quadric roughness
(:func:`scan2morph.align.mesh_noise`) follows it: it read 0.03 mm where the point-to-plane
residual of a right alignment is 0.22 mm, and the gate refused a take aligned to 0.04 degrees.
:func:`scan2morph.align.noise.smoothing_gain` measures that bias on the mesh's own sampling.

These scenes have ground truth: a face-like surface whose vertices sit on a range image's pixels,
two independent noise images smoothed as the repair smooths them, sampled at the vertices and
moved along the normals; the true pose is the identity.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial.transform import Rotation

from scan2morph.align import AlignMeshes, mesh_noise, rmse_gate, vertex_normals
from scan2morph.align.noise import MAX_SMOOTHING_GAIN, smoothing_gain
from tests.unit.test_align import _face

NX, NY = 45, 56  # _face's grid: 3.64 mm between vertices


def _pixels(v: np.ndarray, mm_per_px: float) -> np.ndarray:
    """The vertices' pixels (x, y) on a range image of ``mm_per_px`` (the face 5 px in)."""
    return np.stack([(v[:, 0] + 80) / mm_per_px + 5, (v[:, 1] + 100) / mm_per_px + 5], axis=1)


def _noisy(v, faces, xy, sd_mm: float, sigma_px: float, rng) -> np.ndarray:
    """``v`` moved along its normals by white noise of ``sd_mm`` per pixel, smoothed over
    ``sigma_px`` (3 sigma window, as the repair's) and sampled bilinearly at the pixels ``xy``."""
    shape = (int(xy[:, 1].max()) + 10, int(xy[:, 0].max()) + 10)
    image = ndimage.gaussian_filter(sd_mm * rng.standard_normal(shape), sigma_px, truncate=3.0)
    z = ndimage.map_coordinates(image, (xy[:, 1], xy[:, 0]), order=1)
    return v + z[:, None] * vertex_normals(v, faces), z


@pytest.mark.parametrize(
    ("mm_per_px", "sigma_px", "low", "high"),
    [(1.0, 1.5, 1.0, 1.4), (2.0, 1.5, 2.5, 4.5), (2.0, 0.7, 1.1, 1.5)],
)
def test_the_gain_makes_the_reading_the_noise(mm_per_px, sigma_px, low, high):
    """3.6 and 1.8 px a vertex (about RGB-D at 640 x 480 and 320 x 240): the roughness reads
    the smoothed noise low, and times the gain it is the noise (at most 35% above it: the
    reading holds the surface's own misfit too; never below 0.95 of it); the gain's own noise
    images are not the scene's."""
    v, f = _face(NX, NY)
    xy = _pixels(v, mm_per_px)
    valid = np.ones(len(v), dtype=bool)
    gain = smoothing_gain(v, valid, xy, sigma_px)
    assert low < gain < high
    rng = np.random.default_rng(11)
    for _ in range(3):
        noisy, z = _noisy(v, f, xy, 0.5, sigma_px, rng)
        read = mesh_noise(noisy, valid).region(valid)
        assert 0.95 < gain * read / z.std() < 1.35, (gain, read, z.std())


def test_white_noise_needs_no_gain_and_a_gain_is_bounded():
    v, _ = _face(NX, NY)
    valid = np.ones(len(v), dtype=bool)
    xy = _pixels(v, 1.0)
    assert smoothing_gain(v, valid, xy, 0.0) == 1.0
    # one pixel a vertex smoothed over three: the reading is the surface's own misfit
    assert smoothing_gain(v, valid, _pixels(v, 3.64), 3.0) == MAX_SMOOTHING_GAIN
    # deterministic: the gain's noise images have a fixed seed
    assert smoothing_gain(v, valid, xy, 1.5) == smoothing_gain(v, valid, xy, 1.5)
    # too few valid vertices to read: no correction
    few = np.zeros(len(v), dtype=bool)
    few[:5] = True
    assert smoothing_gain(v, few, xy, 1.5) == 1.0


def _pair(seed: int, gains: bool):
    """A neutral and a take of one face at 1.6 px a vertex (the audit's 320 x 240 RGB-D), each
    with 1 mm of pixel noise smoothed over 1.5 px (0.18 mm at the vertices); the ICP region and
    its centre. With ``gains`` the meshes carry their smoothing gains (about 5), as the
    alignment stage gives them."""
    v, f = _face(NX, NY)
    xy = _pixels(v, 2.3)
    rng = np.random.default_rng(seed)
    take, neutral = (_noisy(v, f, xy, 1.0, 1.5, rng)[0] for _ in range(2))
    valid = np.ones(len(v), dtype=bool)
    g = [smoothing_gain(m, valid, xy, 1.5) if gains else 1.0 for m in (take, neutral)]
    upper = np.flatnonzero((v[:, 1] > -15) & (np.hypot(v[:, 0], v[:, 1] + 45) > 40))
    return AlignMeshes(take, valid, neutral, valid, f, *g), upper, v[upper].mean(axis=0)


def _turned(deg: float, centre: np.ndarray) -> np.ndarray:
    """A rotation by ``deg`` degrees about a tilted axis through ``centre`` (4, 4)."""
    t = np.eye(4)
    axis = np.array([1.0, 0.3, 0.0]) / np.hypot(1.0, 0.3)
    t[:3, :3] = Rotation.from_rotvec(np.radians(deg) * axis).as_matrix()
    t[:3, 3] = centre - t[:3, :3] @ centre
    return t


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_right_pose_of_smoothed_depth_passes_with_the_gains(seed):
    """The audit's case: without the gains the roughness reads a fifth of the noise and the
    right pose is refused; with them the expected RMSE is the residual's (at most 45% above it)
    and it passes, while a pose 2 degrees off (1.1 mm) is still refused. (1 degree, 0.6 mm,
    is within three times this noise, as on any scan this noisy.)"""
    plain, upper, centre = _pair(seed, gains=False)
    refused = rmse_gate(plain, upper, np.eye(4), source="s01/car")
    assert refused.problem is not None
    assert refused.residual_rmse > 3.0 * np.hypot(refused.noise_take, refused.noise_neutral)
    meshes, upper, centre = _pair(seed, gains=True)
    right = rmse_gate(meshes, upper, np.eye(4), source="s01/car")
    assert right.problem is None, right.problem
    expected = np.hypot(right.noise_take, right.noise_neutral)
    assert 0.9 < expected / right.residual_rmse < 1.45
    wrong = rmse_gate(meshes, upper, _turned(2.0, centre), source="s01/car")
    assert wrong.problem is not None
    assert wrong.problem.startswith(f"point-to-plane RMSE {wrong.residual_rmse:.3f} mm")


def test_the_alignment_stage_corrects_the_gate_and_nothing_else():
    """The stage reads each fit's ``mesh/noise_gain``: the gate's noise is the roughness's times
    the gain (its expected RMSE and limit with it), while the pose, which the robust kernel's
    scale from the roughness alone steers, is bit for bit the one without the gains."""
    from scan2morph.stages import align
    from scan2morph.stages.part import Take
    from scan2morph.store import paths
    from scan2morph.template import build_template, subdivide_template
    from tests.support.configs import repo_config

    template = build_template()
    params = align.Params.from_config(repo_config())
    fine = subdivide_template(template, params.levels)
    xy = (fine.vertices - fine.vertices.mean(axis=0)) * 40.0  # the template plane, mm
    dome = 60.0 * np.exp(-(xy**2).sum(axis=1) / (2 * 70.0**2))
    surface = np.column_stack([xy, dome])
    rng = np.random.default_rng(5)
    data = {}
    for take in ("neutral", "car"):
        data[paths.mesh(take, "vertices")] = surface + rng.normal(0, 0.05, surface.shape)
        data[paths.mesh(take, "valid")] = np.ones(len(surface), dtype=bool)
    runs = {}
    for gains in ((1.0, 1.0), (4.0, 2.5)):
        with_gains = dict(data)
        if gains != (1.0, 1.0):
            for take, g in zip(("car", "neutral"), gains, strict=True):
                with_gains[paths.mesh(take, "noise_gain")] = np.float64(g)
        take = Take("s1", "car", "viseme", "car", "neutral", data=with_gains)
        runs[gains] = align.run(template, take, params)
    plain, gained = runs.values()
    group = paths.align_group("car")
    a, b = plain.attrs[group], gained.attrs[group]
    assert b["noise_take_mm"] == 4.0 * a["noise_take_mm"]
    assert b["noise_neutral_mm"] == 2.5 * a["noise_neutral_mm"]
    assert b["expected_rmse_mm"] == pytest.approx(
        np.hypot(b["noise_take_mm"], b["noise_neutral_mm"])
    )
    assert b["rmse_limit_mm"] > a["rmse_limit_mm"]
    assert b["kernel_k_mm"] == a["kernel_k_mm"]
    transform = paths.align("car", "transform")
    np.testing.assert_array_equal(gained.datasets[transform], plain.datasets[transform])
