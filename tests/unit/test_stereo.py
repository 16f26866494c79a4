"""Stereo calibration I/O and dense stereo reconstruction, against ray-cast scenes.

The scene (``tests/support/stereo_scene.py``): two distorted pinhole cameras 120 mm apart, each turned
3 degrees inwards, see a speckle-textured sphere (r = 150 mm, 670-820 mm away) in front of a
textured plane (1150 mm). Ground truth is the exact ray hit of every left pixel centre. The
plate scene's tests are in test_stereo_steps.py, the other rigs' in test_stereo_rigs.py (apart,
so that a parallel run spreads the scenes over its workers).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.io.calibration import (
    StereoCalibration,
    read_stereo_calibration,
    validate_stereo_calibration,
    write_stereo_calibration,
)
from scan2morph.scan.stereo import DEFAULT_STEREO, reconstruct_stereo, stereo_params
from scan2morph.scan.stereo.depth_range import _search_depths
from scan2morph.scan.stereo.rectify import _rectify
from scan2morph.scan.stereo.resample import _resample_left
from tests.support.stereo_scene import (
    DEPTHS,
    SPHERE_CENTRE_MM,
    SPHERE_RADIUS_MM,
    pixel_rays,
    render_scene,
    rig_cameras,
    surface_errors,
)


@pytest.fixture(scope="module")
def scene():
    return render_scene(seed=7)


@pytest.fixture(scope="module")
def result(scene):
    return reconstruct_stereo(scene.left, scene.right, scene.calib, DEPTHS, source="synthetic/s1")


@pytest.fixture(scope="module")
def regions(scene):
    """Masks of the left image: sphere seen within 60 degrees of its normal, all sphere, plane."""
    cams, _ = rig_cameras()
    centre = cams[0]["R"].T @ (SPHERE_CENTRE_MM - cams[0]["C"])  # left camera frame
    normal = (scene.xyz - centre) / SPHERE_RADIUS_MM
    cos_view = -np.sum(normal * scene.rays, axis=-1)
    sphere = scene.surface == 0
    return {
        "front": sphere & (cos_view > np.cos(np.deg2rad(60.0))),
        "sphere": sphere,
        "plane": scene.surface == 1,
        "centre": centre,
    }


def _angles(a, b):
    """Angle (rad) between the rows of a and b, accurate near zero."""
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    return np.arctan2(cross, np.sum(a * b, axis=1))


# --- the synthetic scene itself (checked against OpenCV's projection) -----------------------


def test_scene_ground_truth_projects_onto_its_pixels(scene):
    ok = scene.surface >= 0
    ys, xs = np.nonzero(ok)
    pts = np.ascontiguousarray(scene.xyz[ok]).reshape(-1, 1, 3)
    cal = scene.calib
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cal.K1, cal.D1)
    np.testing.assert_allclose(proj[:, 0], np.stack([xs, ys], axis=1), atol=1e-8)
    # the right camera: OpenCV's projection through (R, T) and the renderer's rays agree
    proj2, _ = cv2.projectPoints(pts, cv2.Rodrigues(cal.R)[0], cal.T, cal.K2, cal.D2)
    x2 = scene.xyz[ok] @ cal.R.T + cal.T
    rays2 = pixel_rays(proj2[:, 0, 0], proj2[:, 0, 1], cal.K2, cal.D2)
    assert _angles(rays2, x2).max() < 1e-9


# --- calibration files ----------------------------------------------------------------------


def test_calibration_round_trip(tmp_path, scene):
    path = tmp_path / "rig.yaml"
    write_stereo_calibration(path, scene.calib)
    assert path.read_text().startswith("%YAML:1.0")
    back = read_stereo_calibration(path)
    for name in ("K1", "D1", "K2", "D2", "R", "T"):
        np.testing.assert_array_equal(getattr(back, name), getattr(scene.calib, name))
    assert back.T.shape == (3,)
    assert back.image_size == (640, 480)
    assert back.baseline_mm == pytest.approx(np.linalg.norm(scene.calib.T))


def test_calibration_reads_opencv_sample_names_and_plain_sequences(tmp_path):
    text = (
        "%YAML:1.0\n---\n"
        "M1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 800., 0., 320., 0., 800., 240., 0., 0., 1. ]\n"
        "D1: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ -0.1, 0.01, 0., 0. ]\n"
        "M2: [[810., 0., 318.], [0., 810., 242.], [0., 0., 1.]]\n"
        "D2: [-0.1, 0.01, 0., 0., 0.]\n"
        "R: [1., 0., 0., 0., 1., 0., 0., 0., 1.]\n"
        "T: !!opencv-matrix\n   rows: 1\n   cols: 3\n   dt: f\n   data: [ -120., 0.5, 1. ]\n"
    )
    path = tmp_path / "sample.yml"
    path.write_text(text)
    calib = read_stereo_calibration(path)
    np.testing.assert_array_equal(calib.K1, [[800, 0, 320], [0, 800, 240], [0, 0, 1]])
    np.testing.assert_array_equal(calib.K2[0], [810, 0, 318])
    assert calib.D1.shape == (4,) and calib.D2.shape == (5,)
    np.testing.assert_array_equal(calib.R, np.eye(3))
    np.testing.assert_allclose(calib.T, [-120.0, 0.5, 1.0])
    assert calib.image_size is None


def _write_yaml(path, **entries):
    """A FileStorage YAML with the given matrices (None: leave the key out)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML_1_0)
    for key, value in entries.items():
        if value is not None:
            fs.write(key, value)
    fs.release()
    return path


def _good_entries(calib):
    return {
        "K1": calib.K1,
        "D1": calib.D1.reshape(1, -1),
        "K2": calib.K2,
        "D2": calib.D2.reshape(1, -1),
        "R": calib.R,
        "T": calib.T.reshape(3, 1),
    }


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"K1": None}, r"K1: missing"),
        ({"T": np.array([[-120.0], [0.0]])}, r"T: expected 3 values"),
        ({"K2": np.eye(3)[:2]}, r"K2: expected a 3x3 camera matrix"),
        ({"D1": np.zeros((1, 3))}, r"D1: expected 4, 5, 8, 12 or 14 distortion coefficients"),
        ({"R": np.diag([1.0, 1.0, 1.1])}, r"R: not a rotation matrix"),
        ({"R": np.diag([1.0, 1.0, -1.0])}, r"R: not a rotation matrix.*det"),
        (
            {"K1": np.array([[np.nan, 0, 320], [0, 800, 240], [0, 0, 1]])},
            r"K1: contains non-finite",
        ),
        ({"T": np.array([[-0.12], [0.0], [0.0]])}, r"T: baseline .* below 1 mm"),
        ({"image_width": 640}, r"image_height: missing while image_width is given"),
        ({"image_width": 640, "image_height": -5}, r"image_height: expected a positive integer"),
    ],
)
def test_calibration_bad_content(tmp_path, scene, change, match):
    entries = {**_good_entries(scene.calib), **change}
    path = _write_yaml(tmp_path / "bad.yaml", **entries)
    with pytest.raises(InputError, match=match) as info:
        read_stereo_calibration(path)
    assert str(path) in str(info.value)


def test_calibration_file_errors(tmp_path):
    with pytest.raises(InputError, match=r"missing\.yaml: file not found"):
        read_stereo_calibration(tmp_path / "missing.yaml")
    png = tmp_path / "left.png"
    cv2.imwrite(str(png), np.zeros((8, 8), np.uint8))
    with pytest.raises(InputError, match=r"left\.png: not an OpenCV FileStorage calibration"):
        read_stereo_calibration(png)
    other = tmp_path / "config.yaml"
    other.write_text("subjects: config/subjects.tsv\nsynthetic:\n  subjects: 2\n")
    with pytest.raises(InputError, match=r"config\.yaml: K1: missing .*keys found: subjects"):
        read_stereo_calibration(other)
    text = tmp_path / "notes.txt"
    text.write_text("this is not a calibration\n")
    with pytest.raises(InputError, match=r"notes\.txt: not an OpenCV FileStorage calibration"):
        read_stereo_calibration(text)
    string_matrix = _write_yaml(tmp_path / "s.yaml", K1="eye")
    with pytest.raises(InputError, match=r"K1: expected a matrix or a sequence of numbers"):
        read_stereo_calibration(string_matrix)


def test_validate_names_the_source(scene):
    c = scene.calib
    bad = StereoCalibration(c.K1, c.D1, c.K2, c.D2, c.R, c.T[:2])
    with pytest.raises(InputError, match=r"^s1/neutral: T: expected 3 values"):
        validate_stereo_calibration(bad, "s1/neutral")


# --- reconstruction -------------------------------------------------------------------------


def test_depth_accuracy_and_coverage(scene, result, regions):
    xyz, report = result
    err, coverage = surface_errors(xyz, scene.xyz, regions["front"])
    rms = float(np.sqrt(np.mean(err**2)))
    assert coverage > 0.99
    # measured 0.24 mm at ~750 mm (0.05 px of disparity; 0.35 mm with the windowed
    # refinement alone)
    assert rms < 0.3
    # the whole sphere, grazing silhouette included: still covered (measured 0.90: the growth
    # reaches into the steep rim), no gross outliers
    err, coverage = surface_errors(xyz, scene.xyz, regions["sphere"])
    assert coverage > 0.88
    assert np.sqrt(np.mean(err**2)) < 0.5 and err.max() < 20.0
    # the plane at 1150-1250 mm (12 mm of depth per px of disparity)
    err, coverage = surface_errors(xyz, scene.xyz, regions["plane"])
    assert coverage > 0.8
    assert np.median(err) < 1.0 and np.percentile(err, 99) < 6.0
    assert report["coverage"] == pytest.approx(np.isfinite(xyz[..., 2]).mean())
    assert report["baseline_mm"] == pytest.approx(scene.calib.baseline_mm)
    assert report["numDisparities"] % 16 == 0 and report["wls"] is False
    assert report["grown_px"] > 0 and report["filled_px"] >= 0
    assert {"refine", "grow", "validate", "resample"} <= set(report["timings_s"])
    assert report["focal_rect_px"] == pytest.approx(scene.calib.K1[0, 0], rel=0.02)
    assert report["depth_range_mm"] == [600.0, 1300.0]  # an explicit range wins
    assert report["depth_range_source"] == "config" and report["coarse_scale"] == 0


def test_output_is_the_left_image_grid(scene, result):
    xyz, _ = result
    assert xyz.shape == scene.left.shape[:2] + (3,) and xyz.dtype == np.float64
    valid = np.isfinite(xyz)
    assert np.array_equal(valid[..., 0], valid[..., 1]) and np.array_equal(
        valid[..., 0], valid[..., 2]
    )
    # every point lies on the undistorted ray of its own left pixel (independent inversion)
    ys, xs = np.nonzero(valid[..., 2])
    rays = pixel_rays(xs.astype(float), ys.astype(float), scene.calib.K1, scene.calib.D1)
    p = xyz[ys, xs]
    assert _angles(rays, p).max() < 1e-9
    assert np.all(xyz[ys, xs, 2] > 0)


def test_occluded_background_is_left_empty(scene, result, regions):
    """Plane points the sphere hides from the right camera get no point (LR check, trimming)."""
    xyz, _ = result
    c2 = -scene.calib.R.T @ scene.calib.T  # right camera centre, left frame
    seg = scene.xyz - c2
    oc = c2 - regions["centre"]
    a = np.sum(seg * seg, axis=-1)
    b = np.sum(seg * oc, axis=-1)
    disc = b * b - a * (oc @ oc - SPHERE_RADIUS_MM**2)
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(disc)) / a
    occluded = regions["plane"] & (disc > 0) & (t > 0) & (t < 1)
    assert occluded.sum() > 5000
    assert np.isfinite(xyz[occluded, 2]).mean() < 0.02


def test_refinement_and_wls_measured(scene, result, regions):
    """Both sub-pixel refinements (default on) help; WLS (default off) does not on speckle.

    Measured front RMS: 0.53 mm SGBM alone, 0.34 mm with the windowed refinement, 0.24 mm
    with the per-pixel slanted windows on top (the default), 0.24-0.25 mm with WLS.
    """
    assert DEFAULT_STEREO["wls"] is False and DEFAULT_STEREO["refine_iterations"] > 0
    assert DEFAULT_STEREO["patch_iterations"] > 0
    rms = {}
    variants = {
        "default": None,
        "windowed": {"patch_iterations": 0},
        "sgbm_only": {"refine_iterations": 0, "patch_iterations": 0},
        "wls": {"wls": True},
    }
    for name, extra in variants.items():
        if extra is None:
            xyz = result[0]
        else:
            xyz, report = reconstruct_stereo(
                scene.left, scene.right, scene.calib, {**DEPTHS, **extra}
            )
        err, _ = surface_errors(xyz, scene.xyz, regions["front"])
        rms[name] = float(np.sqrt(np.mean(err**2)))
    assert rms["default"] < 0.8 * rms["windowed"] and rms["windowed"] < 0.8 * rms["sgbm_only"]
    assert rms["default"] < rms["wls"] < 1.0
    assert report["wls"] is True


@functools.cache
def _small_scene():
    """The sphere scene at 320 x 240 with another speckle texture (seed 99), rendered once."""
    return render_scene(seed=99, width=320, height=240)


def test_grey_input_and_unknown_image_size():
    """Grey images and a calibration without its image size give the RGB pair's points (an
    equality: on the small scene)."""
    small = _small_scene()
    c = small.calib
    rgb, _ = reconstruct_stereo(small.left, small.right, c, DEPTHS)
    calib = StereoCalibration(c.K1, c.D1, c.K2, c.D2, c.R, c.T)  # no image_size
    xyz, _ = reconstruct_stereo(small.left[..., 0], small.right[..., 0], calib, DEPTHS)
    assert np.isfinite(rgb).all(axis=-1).mean() > 0.5
    np.testing.assert_array_equal(np.isfinite(xyz), np.isfinite(rgb))
    np.testing.assert_allclose(xyz, rgb, equal_nan=True)


def test_rig_with_camera_one_on_the_right(scene, regions):
    """Swapping the cameras gives negative disparities; the sphere is still measured."""
    c = scene.calib
    swapped = StereoCalibration(c.K2, c.D2, c.K1, c.D1, c.R.T, -c.R.T @ c.T, c.image_size)
    xyz, report = reconstruct_stereo(scene.right, scene.left, swapped, DEPTHS)
    assert report["minDisparity"] < 0
    pts = xyz[np.isfinite(xyz[..., 2])]
    in_left = (pts - c.T) @ c.R  # x1 = R^T (x2 - T), as rows
    off = np.abs(np.linalg.norm(in_left - regions["centre"], axis=1) - SPHERE_RADIUS_MM)
    on_sphere = off < 20.0
    assert on_sphere.sum() > 0.8 * regions["sphere"].sum()
    assert np.sqrt(np.mean(off[on_sphere] ** 2)) < 0.4  # distance along the normal, mm


def _plane_disparity(calib):
    """Rectification and the disparity (h, w) of the plane Z = 900 + 0.2 X - 0.1 Y (rectified
    left frame, mm), whose 1/Z and disparity are affine in the rectified pixel; and a function
    of points (n, 3) in the left camera frame giving their distance from the plane along Z."""
    rect = _rectify(calib, (640, 480), stereo_params(DEPTHS), "test")
    w, h = rect["size"]
    f, cx, cy = rect["P1"][0, 0], rect["P1"][0, 2], rect["P1"][1, 2]
    tx = rect["P2"][0, 3] / rect["P2"][0, 0]
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    inv_z = (1.0 - 0.2 * (u - cx) / f + 0.1 * (v - cy) / f) / 900.0
    disparity = (-f * tx * inv_z).astype(np.float32)

    def off_plane(points):
        p = points @ rect["R1"].T  # into the rectified frame
        return p[:, 2] - 900.0 - 0.2 * p[:, 0] + 0.1 * p[:, 1]

    return rect, disparity, off_plane


def test_disparity_of_a_plane_resamples_exactly_onto_it(scene):
    """Bilinear disparity interpolation is exact on planes (disparity is affine there)."""
    rect, disparity, off_plane = _plane_disparity(scene.calib)
    # oracle: OpenCV's own reprojection of that disparity lies on the plane
    grid = cv2.reprojectImageTo3D(disparity, rect["Q"], handleMissingValues=False)
    plane = grid[..., 2] - 900.0 - 0.2 * grid[..., 0] + 0.1 * grid[..., 1]
    assert np.abs(plane).max() < 1e-3  # mm; float32 disparity and output
    xyz = _resample_left(disparity, rect, scene.calib, (640, 480), 1.0)
    valid = np.isfinite(xyz[..., 2])
    assert valid.mean() > 0.99
    assert np.abs(off_plane(xyz[valid])).max() < 1e-3  # mm (measured 5e-5: float32 disparity)


def test_resampling_keeps_the_border_of_the_valid_region(scene):
    """A left pixel gets a point when its nearest rectified pixel is valid, on the surface.

    The former rule (all four rectified neighbours valid) eroded every valid region by half a
    pixel; the missing neighbours are now completed from the plane of the other three or the
    nearest one.
    """
    rect, disparity, off_plane = _plane_disparity(scene.calib)
    w, h = rect["size"]
    disparity[:, w // 2 :] = np.nan  # a straight border
    disparity[h // 2 : h // 2 + 3, w // 4 : w // 4 + 3] = np.nan  # a small hole
    disparity[h // 4, w // 4] = np.nan  # a single pixel
    xyz = _resample_left(disparity, rect, scene.calib, (640, 480), 1.0)
    # where every left pixel lands in the rectified image (independent of the pipeline)
    ys, xs = np.mgrid[0:480, 0:640].astype(np.float64)
    pix = np.stack([xs.ravel(), ys.ravel()], axis=-1).reshape(-1, 1, 2)
    uv = cv2.undistortPoints(
        pix, scene.calib.K1, scene.calib.D1, R=rect["R1"], P=rect["P1"]
    ).reshape(480, 640, 2)
    nearest = np.rint(uv).astype(int)
    inside = (nearest[..., 0] >= 1) & (nearest[..., 0] < w - 1)
    inside &= (nearest[..., 1] >= 1) & (nearest[..., 1] < h - 1)
    expected = np.zeros((480, 640), bool)
    expected[inside] = np.isfinite(disparity[nearest[inside][:, 1], nearest[inside][:, 0]])
    valid = np.isfinite(xyz[..., 2])
    assert np.array_equal(valid[inside], expected[inside])
    # on the plane: exact where the neighbours are complete or complete a plane; along the
    # straight border (two neighbours missing) within the nearest one's half-pixel step of
    # disparity (measured 0.12 mm)
    err = np.abs(off_plane(xyz[valid]))
    assert np.median(err) < 1e-3 and err.max() < 0.2


# --- bad input ------------------------------------------------------------------------------


def test_images_of_different_sizes(scene):
    with pytest.raises(
        InputError, match=r"^s1/t2: left/right: image sizes differ: left 640x480, right 320x480"
    ):
        reconstruct_stereo(scene.left, scene.right[:, :320], scene.calib, DEPTHS, source="s1/t2")


def test_calibration_size_disagrees_with_images(scene):
    small_l = np.ascontiguousarray(scene.left[:240, :320])
    small_r = np.ascontiguousarray(scene.right[:240, :320])
    with pytest.raises(
        InputError,
        match=r"calibration image_width/image_height 640x480 differ from the images 320x240",
    ):
        reconstruct_stereo(small_l, small_r, scene.calib, DEPTHS, source="s1/t2")


def test_image_type_and_params_are_checked(scene):
    with pytest.raises(InputError, match=r"right: expected an \(H, W, 3\) or \(H, W\) uint8 image"):
        reconstruct_stereo(scene.left, scene.right.astype(np.float32), scene.calib, DEPTHS)
    with pytest.raises(InputError, match=r"blocksize: unknown stereo parameter"):
        reconstruct_stereo(scene.left, scene.right, scene.calib, {"blocksize": 7})
    with pytest.raises(InputError, match=r"numDisparities: expected a positive multiple of 16"):
        reconstruct_stereo(scene.left, scene.right, scene.calib, {"numDisparities": 100})


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"grow_min_zncc": 1.5}, r"grow_min_zncc: expected a ZNCC in \[-1, 1\], got 1.5"),
        ({"min_patch_zncc": -2}, r"min_patch_zncc: expected a ZNCC in \[-1, 1\]"),
        ({"patch_radius_px": 0}, r"patch_radius_px: expected >= 1, got 0"),
        ({"fill_max_px": -1}, r"fill_max_px: expected >= 0, got -1"),
        ({"edge_jump_px": 0.0}, r"edge_jump_px: expected > 0, got 0.0"),
        ({"pixel_texture_sigma_px": -0.5}, r"pixel_texture_sigma_px: expected > 0"),
        ({"min_depth_mm": 500.0}, r"min_depth_mm, max_depth_mm: expected 0 < min < max \(mm\) or"),
        ({"min_depth_mm": 900.0, "max_depth_mm": 500.0}, r"min_depth_mm, max_depth_mm: expected"),
        ({"depth_margin_mm": -1.0}, r"depth_margin_mm: expected >= 0, got -1.0"),
        ({"patch_curvature": "yes"}, r"patch_curvature: expected true or false, got 'yes'"),
        ({"rectify_interpolation": "area"}, r"rectify_interpolation: expected one of linear, c"),
    ],
)
def test_validation_params_are_checked(change, match):
    with pytest.raises(InputError, match=r"^s1/t4: " + match):
        stereo_params(change, source="s1/t4")


def test_vertical_rig_is_refused(scene):
    c = scene.calib
    calib = StereoCalibration(c.K1, c.D1, c.K2, c.D2, np.eye(3), [0.0, -120.0, 0.0], (640, 480))
    with pytest.raises(InputError, match=r"stacked vertically"):
        reconstruct_stereo(scene.left, scene.right, calib, DEPTHS)


@pytest.mark.parametrize("case", ["black_right", "flat_grey", "other_scene"])
def test_images_that_do_not_overlap(scene, case):
    left, right = scene.left, scene.right
    if case == "black_right":
        right = np.zeros_like(right)
    elif case == "flat_grey":
        left, right = np.full_like(left, 128), np.full_like(right, 128)
    else:  # a right image of a different speckle texture
        right = _small_scene().right
        right = cv2.resize(right, (640, 480), interpolation=cv2.INTER_NEAREST)
    with pytest.raises(
        InputError, match=r"^s1/t3: left/right: the images do not overlap as a stereo pair"
    ):
        reconstruct_stereo(left, right, scene.calib, DEPTHS, source="s1/t3")


def test_given_disparities_need_no_depth_range(scene):
    """minDisparity and numDisparities given: nothing is derived; the report gives the depths
    they cover (the far end at infinity: None)."""
    rect = _rectify(scene.calib, (640, 480), stereo_params(), "test")
    blank = np.zeros(rect["size"][::-1], np.uint8)
    p = stereo_params({"minDisparity": 0, "numDisparities": 160})
    depths = _search_depths(rect, blank, blank, blank > 0, blank > 0, p, "s1/t5")
    assert depths.source == "config" and depths.depth_mm[1] is None
    f_b = rect["P1"][0, 0] * scene.calib.baseline_mm
    assert depths.depth_mm[0] == pytest.approx(f_b / 160, rel=0.01)


@pytest.mark.parametrize("case", ["black_right", "flat_grey", "other_scene"])
def test_images_that_do_not_overlap_give_no_depth_range(scene, case):
    """Default parameters: no range can be derived (blank views), or the fine pass finds no
    overlap in the range derived from chance matches; the error names the source."""
    left, right = scene.left, scene.right
    if case == "black_right":
        right = np.zeros_like(right)
    elif case == "flat_grey":
        left, right = np.full_like(left, 128), np.full_like(right, 128)
    else:
        right = _small_scene().right
        right = cv2.resize(right, (640, 480), interpolation=cv2.INTER_NEAREST)
    with pytest.raises(
        InputError, match=r"^s1/t3: left/right: the images do not overlap as a stereo pair"
    ) as info:
        reconstruct_stereo(left, right, scene.calib, source="s1/t3")
    if case != "other_scene":
        assert "no depth range could be derived" in str(info.value)


def test_a_rigs_rectified_grid_is_kept_and_another_rigs_is_its_own(scene):
    """The left pixels' rectified positions are computed once per rig (resample's memo): the
    same rig again gives the kept arrays (read-only), equal to cv2.undistortPoints run afresh;
    a rig with other distortion gets its own."""
    from dataclasses import replace

    from scan2morph.scan.stereo.resample import _rectified_grid

    rect = _rectify(scene.calib, (640, 480), stereo_params(DEPTHS), "test")
    u, v = _rectified_grid(scene.calib, rect, (640, 480))
    assert _rectified_grid(scene.calib, rect, (640, 480))[0] is u and not u.flags.writeable
    pix = np.stack(np.meshgrid(np.arange(640.0), np.arange(480.0)), axis=-1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-12)
    fresh = cv2.undistortPoints(
        pix, scene.calib.K1, scene.calib.D1, R=rect["R1"], P=rect["P1"], criteria=criteria
    )
    np.testing.assert_array_equal(u, fresh[:, 0, 0])
    np.testing.assert_array_equal(v, fresh[:, 0, 1])
    other = replace(scene.calib, D1=np.asarray(scene.calib.D1) + 0.01)
    u2, _ = _rectified_grid(other, rect, (640, 480))
    assert u2 is not u and np.abs(u2 - u).max() > 0.1
