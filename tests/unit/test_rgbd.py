"""RGB-D takes: intrinsics, depth -> colour-grid resampling against an analytic plane, the
synthetic sensor against its truth, and the repair of depth-camera data (flying pixels, noise)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from scan2morph.evaluate.scan import face_region, stereo_accuracy
from scan2morph.io.depth_image import read_depth, write_depth_png
from scan2morph.io.rgbd import (
    PinholeCamera,
    RGBDIntrinsics,
    depth_to_color_grid,
    read_rgbd_intrinsics,
    read_rgbd_take,
    write_rgbd_intrinsics,
)
from scan2morph.scan.repair import repair_range, smooth_depth, trim_depth_edges
from scan2morph.synth.rgbd import make_rgbd_take, write_rgbd_take

#: A tiny sensor: 160 x 120 depth and colour images, the face at 600 mm.
TINY_RGBD = dict(
    width=160, height=120, focal_px=250.0, color_width=160, color_height=120, color_focal_px=258.0
)


def _camera(w, h, f, D=None):
    K = np.array([[f, 0, (w - 1) / 2], [0, f * 1.01, (h - 1) / 2 + 0.7], [0, 0, 1.0]])
    return PinholeCamera(K, np.zeros(5) if D is None else np.asarray(D, float), (w, h))


def _sensor(D_color=None):
    R = Rotation.from_euler("xyz", [0.8, -1.5, 0.4], degrees=True).as_matrix()
    return RGBDIntrinsics(
        _camera(120, 90, 110.0),
        _camera(200, 150, 190.0, D_color),
        R,
        np.array([-25.0, 3.0, 2.0]),
        1.0,
    )


def _plane_depth(intr, n, d):
    """Exact depth image of the plane n . x = d seen by the depth camera (mm)."""
    cam = intr.depth
    w, h = cam.size
    v, u = np.mgrid[0:h, 0:w].astype(float)
    rays = np.stack(
        [(u - cam.K[0, 2]) / cam.K[0, 0], (v - cam.K[1, 2]) / cam.K[1, 1], np.ones_like(u)], -1
    )
    return d / (rays @ n)


@pytest.mark.parametrize("k1", [0.0, -0.08])
def test_plane_resampled_onto_the_colour_grid_exactly(k1):
    """Every colour pixel's point lies on the plane and projects onto that pixel's centre."""
    intr = _sensor([k1, 0.01, 0, 0, 0] if k1 else None)
    n = np.array([0.2, -0.1, 1.0])
    n /= np.linalg.norm(n)
    d = 700.0 * n[2]
    xyz = depth_to_color_grid(_plane_depth(intr, n, d), intr)
    assert xyz.shape == (150, 200, 3)
    ok = np.isfinite(xyz).all(axis=-1)
    assert ok[30:120, 40:160].all()  # the depth camera sees the middle of the colour image
    pts = xyz[ok]
    assert_allclose(pts @ n, d, atol=1e-6)
    cam = pts @ intr.R.T + intr.T
    c = intr.color
    pix = cv2.projectPoints(cam, np.zeros(3), np.zeros(3), c.K, c.D)[0].reshape(-1, 2)
    v, u = np.nonzero(ok)
    assert_allclose(pix, np.column_stack([u, v]), atol=1e-4)


def test_nearest_surface_wins_and_steps_are_not_bridged():
    """A box in front of a wall: colour pixels see the box, not the wall behind it, and no pixel
    gets a depth between the two (no triangle across the step)."""
    intr = _sensor()
    depth = np.full((90, 120), 1500.0)
    depth[30:60, 40:80] = 600.0
    xyz = depth_to_color_grid(depth, intr)
    z = xyz[..., 2][np.isfinite(xyz[..., 2])]
    assert ((np.abs(z - 600) < 1e-6) | (np.abs(z - 1500) < 1e-6)).all()
    # the colour pixel of the box centre sees the box
    centre = intr.R @ np.array([0.0, 0.0, 600.0]) + intr.T  # the box's centre, roughly
    u, v = (intr.color.K @ (centre / centre[2]))[:2].round().astype(int)
    assert xyz[v, u, 2] == pytest.approx(600.0)


def test_intrinsics_round_trip(tmp_path):
    intr = _sensor([-0.05, 0.01, 0.001, -0.002, 0.0])
    write_rgbd_intrinsics(tmp_path / "i.yaml", intr)
    back = read_rgbd_intrinsics(tmp_path / "i.yaml")
    for a, b in ((back.depth, intr.depth), (back.color, intr.color)):
        assert_allclose(a.K, b.K)
        assert_allclose(a.D, b.D)
        assert a.size == b.size
    assert_allclose(back.R, intr.R)
    assert_allclose(back.T, intr.T)
    assert back.depth_scale_mm == 1.0


def test_depth_formats(tmp_path):
    units = np.arange(12, dtype=np.uint16).reshape(3, 4) * 100
    write_depth_png(tmp_path / "d.png", units)
    np.save(tmp_path / "d.npy", units.astype(np.float32))
    np.savez(tmp_path / "d.npz", depth=units)
    for name in ("d.png", "d.npy", "d.npz"):
        assert_allclose(read_depth(tmp_path / name), units)


@pytest.fixture(scope="module")
def rgbd_take():
    return make_rgbd_take("s1", "neutral", "neutral", "neutral", seed=3, params=dict(TINY_RGBD))


def test_synthetic_sensor_read_back_against_its_truth(rgbd_take, tmp_path):
    """The written take, read back onto the colour grid, matches the true surface over the face
    within the sensor's noise (0.7 mm at 600 mm, plus 1 mm quantisation)."""
    files = [tmp_path / f for f in ("d.png", "c.png", "i.yaml", "l.pts", "t.npz")]
    write_rgbd_take(rgbd_take, *files)
    take = read_rgbd_take(*files[:4])
    truth = rgbd_take["truth"]
    face = face_region(truth["segment"] == 0, truth["landmarks2d"])
    acc = stereo_accuracy(take.xyz, truth["xyz_true"], face)
    print(f"\nRGB-D ingest over the face: {acc}")
    assert acc["coverage"] > 0.85
    assert acc["depth_median_mm"] < 1.0
    repaired, report = repair_range(take.xyz, depth_camera=True)
    acc2 = stereo_accuracy(repaired, truth["xyz_true"], face)
    print(f"after repair: {acc2}")
    assert acc["depth_max_mm"] > 100.0  # the wall seen past the silhouette, and flying pixels
    assert acc2["depth_max_mm"] < 25.0  # ... are gone (what is left: steep sides, noise)
    assert acc2["depth_rms_mm"] < 1.5 and acc2["depth_median_mm"] < acc["depth_median_mm"]
    assert acc2["coverage"] > 0.85
    assert report["n_flying"] > 0


def test_trim_depth_edges_drops_flying_pixels_not_the_near_surface():
    h, w = 40, 60
    v, u = np.mgrid[0:h, 0:w].astype(float)
    z = np.where(u < 30, 600.0, 1000.0)
    z[:, 30] = 800.0  # a column of flying pixels between the two surfaces
    xyz = np.stack([(u - 29.5) / 300 * z, (v - 19.5) / 300 * z, z], axis=-1)
    out, dropped = trim_depth_edges(xyz, 10.0, 2)
    assert dropped[:, 30].all()
    assert not dropped[:, :30].any()  # the near side is kept whole
    assert dropped[:, 31:33].all() and not dropped[:, 33:].any()  # the far side, 2 px
    assert np.isnan(out[dropped]).all()


def test_smooth_depth_reduces_noise_and_keeps_a_step():
    rng = np.random.default_rng(0)
    h, w = 60, 80
    v, u = np.mgrid[0:h, 0:w].astype(float)
    z_true = np.where(u < 40, 600.0, 650.0)
    z = z_true + rng.normal(0, 1.0, z_true.shape)
    xyz = np.stack([(u - 39.5) / 300 * z, (v - 29.5) / 300 * z, z], axis=-1)
    out = smooth_depth(xyz, 1.5, 10.0)
    err = out[..., 2] - z_true
    inner = (np.abs(u - 39.5) > 6) & (u > 5) & (u < w - 6) & (v > 5) & (v < h - 6)
    assert np.std(err[inner]) < 0.3  # 1 mm noise averaged over ~28 px
    assert np.abs(err[:, 38:42]).max() < 5.0  # nothing smeared across the 50 mm step
    # the points stay on their rays
    ray = xyz / np.linalg.norm(xyz, axis=-1, keepdims=True)
    assert_allclose(out / np.linalg.norm(out, axis=-1, keepdims=True), ray, atol=1e-12)


def test_a_depth_cameras_fit_carries_the_gain_of_its_smoothed_noise(rgbd_take, tmp_path):
    """Ingest, repair and fit of the synthetic sensor's take: the fit records how much its
    roughness under-reads the depth noise the repair smoothed (``mesh/noise_gain``, > 1,
    :func:`scan2morph.align.noise.smoothing_gain`); the same grid taken as a range scan (no
    smoothing) has none, nor has a depth camera's whose smoothing is off."""
    from scan2morph.stages import fit, ingest, repair
    from scan2morph.stages.part import Take
    from scan2morph.store import paths
    from scan2morph.template import build_template
    from tests.support.configs import repo_config

    files = [tmp_path / f for f in ("d.png", "c.png", "i.yaml", "l.pts", "t.npz")]
    write_rgbd_take(rgbd_take, *files)
    row = dict(subject="s1", take="neutral", kind="neutral", label="neutral", modality="rgbd")
    roles = dict(
        zip(("depth", "color", "intrinsics", "landmarks"), map(str, files[:4]), strict=True)
    )
    config = repo_config()
    raw = ingest.run(None, Take.from_row(row, files=roles), ingest.Params.from_config(config))
    attrs = raw.attrs[paths.take("neutral")]
    fixed = repair.run(
        None, Take.from_row(row, data=raw.datasets, attrs=attrs), repair.Params.from_config(config)
    )
    data = dict(fixed.datasets)
    data[paths.landmarks("neutral")] = data[paths.clicks("neutral")]
    template = build_template()
    gain_key = paths.mesh("neutral", "noise_gain")

    def fitted(modality, cfg):
        take = Take.from_row(row, "neutral", data=data, attrs=attrs | {"modality": modality})
        return fit.run(template, take, fit.Params.from_config(cfg)).datasets

    gain = float(fitted("rgbd", config)[gain_key])
    print(f"\nnoise gain of the 160 x 120 depth camera's fit: {gain:.2f}")
    assert 1.0 < gain <= 10.0
    assert gain_key not in fitted("range", config)
    off = config | {"repair": config["repair"] | {"depth_smooth_sigma_px": 0.0}}
    assert gain_key not in fitted("rgbd", off)
