"""Bilinear range sampling, texture coordinates, fold check and the one-call take fit."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from scan2morph.errors import InputError
from scan2morph.template import (
    FitRules,
    behind_steps,
    build_template,
    check_no_folds,
    fit_take,
    sample_range,
    subdivide_template,
    texture_uv,
)

W, H = 640, 480
# A tilted plane in an OpenCV-like camera frame (x right, y down, z forward), mm.
PLANE = np.array([[0.7, 0.0, 0.05], [0.0, 0.7, -0.03], [-224.0, -168.0, 1000.0]])


def _plane_xyz(w=W, h=H):
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([x, y, np.ones_like(x)], axis=-1) @ PLANE


def _on_plane(points):
    return np.column_stack([points, np.ones(len(points))]) @ PLANE


@pytest.fixture(scope="module")
def template():
    return build_template()


@pytest.fixture(scope="module")
def xyz():
    return _plane_xyz()


def _landmarks(template, scale=70.0, centre=(320.0, 230.0)):
    """Landmarks that are a similarity image of the template's iBUG points (the warp is affine)."""
    return np.asarray(centre) + scale * template.ibug_xy


def test_bilinear_is_exact_on_a_plane_including_the_last_row_and_column(xyz):
    rng = np.random.default_rng(0)
    pts = np.vstack(
        [
            rng.uniform(0, [W - 1, H - 1], (2000, 2)),
            [[0, 0], [W - 1, H - 1], [W - 1, 10.25], [3.5, H - 1], [17.0, 12.0]],
        ]
    )
    v, valid = sample_range(xyz, pts)
    assert valid.all()
    np.testing.assert_allclose(v, _on_plane(pts), rtol=0, atol=1e-9)
    np.testing.assert_array_equal(v[-1], xyz[12, 17])  # an integer position is that pixel


@pytest.mark.parametrize("corner", [(0, 0), (0, 1), (1, 0), (1, 1)])
def test_a_missing_neighbour_invalidates_the_sample(xyz, corner):
    img = xyz.copy()
    img[20 + corner[0], 30 + corner[1], 2] = np.nan  # one coordinate of one of the 4 neighbours
    v, valid = sample_range(img, np.array([[30.4, 20.6], [32.4, 20.6]]))
    assert valid.tolist() == [False, True]
    assert np.isnan(v[0]).all() and np.isfinite(v[1]).all()  # NaN, never zeros


@pytest.mark.parametrize("missing", [(0,), (1,), (2,), (3,)])
def test_three_neighbours_with_data_are_exact_on_a_plane(xyz, missing):
    # one corner of the cell (30, 20)-(31, 21) without data: the plane through the other three
    # is the plane itself, wherever the point lies in the cell
    img = xyz.copy()
    dx, dy = [(0, 0), (1, 0), (0, 1), (1, 1)][missing[0]]
    img[20 + dy, 30 + dx] = np.nan
    rng = np.random.default_rng(3)
    pts = np.array([30.0, 20.0]) + rng.uniform(0, 1, (500, 2))
    v, valid = sample_range(img, pts, min_weight=1e-9)
    assert valid.all()
    np.testing.assert_allclose(v, _on_plane(pts), rtol=0, atol=1e-9)
    # the paper's rule (min_weight 1) rejects them all
    assert not sample_range(img, pts)[1].any()


@pytest.mark.parametrize("side", ["left", "right", "top", "bottom"])
def test_min_weight_is_the_share_of_bilinear_weight_on_pixels_with_data(xyz, side):
    # one side of the cell (30, 20)-(31, 21) has no data: the share on data is 1 - f, with f
    # the offset from the side that has data
    img = xyz.copy()
    f = np.array([0.1, 0.3, 0.49, 0.51, 0.9])
    along = np.full(5, 0.35)
    if side == "left":  # the right column has data
        img[20:22, 30] = np.nan
        pts, kept = (
            np.column_stack([31 - f, 20 + along]),
            np.column_stack([np.full(5, 31.0), 20 + along]),
        )
    elif side == "right":
        img[20:22, 31] = np.nan
        pts, kept = (
            np.column_stack([30 + f, 20 + along]),
            np.column_stack([np.full(5, 30.0), 20 + along]),
        )
    elif side == "top":  # the bottom row has data
        img[20, 30:32] = np.nan
        pts, kept = (
            np.column_stack([30 + along, 21 - f]),
            np.column_stack([30 + along, np.full(5, 21.0)]),
        )
    else:
        img[21, 30:32] = np.nan
        pts, kept = (
            np.column_stack([30 + along, 20 + f]),
            np.column_stack([30 + along, np.full(5, 20.0)]),
        )
    v, valid = sample_range(img, pts, min_weight=0.5)
    assert valid.tolist() == [True, True, True, False, False]
    # two pixels with data: exact along their edge, constant across it (the nearest edge point)
    np.testing.assert_allclose(v[:3], _on_plane(kept[:3]), rtol=0, atol=1e-9)
    assert np.isnan(v[3:]).all()


def test_two_diagonal_pixels_give_the_value_along_their_diagonal(xyz):
    img = xyz.copy()
    img[20, 31] = img[21, 30] = np.nan  # (30, 20) and (31, 21) have data
    pts = np.array([[30.5, 20.5], [30.3, 20.3], [30.6, 20.4]])
    v, valid = sample_range(img, pts, min_weight=0.3)
    assert valid.all()
    # the projection onto the diagonal: t = (fx + fy) / 2
    t = pts.sum(axis=1) / 2 - 25.0
    np.testing.assert_allclose(v, _on_plane(np.column_stack([30 + t, 20 + t])), atol=1e-9)
    # one pixel with data: its value
    img2 = xyz.copy()
    img2[20, 31] = img2[21, 30:32] = np.nan
    v2, ok2 = sample_range(img2, np.array([[30.2, 20.3]]), min_weight=0.5)
    assert ok2[0] and np.array_equal(v2[0], xyz[20, 30])


def test_a_depth_step_between_neighbours_invalidates_the_sample(xyz):
    # a step of 8 mm between rows 20 and 21 (a lip over the chin; pixels 0.7 mm apart): points
    # between the two rows straddle it; the plane itself (slope ~3 deg) never does
    img = xyz.copy()
    img[21:, :, 2] += 8.0
    pts = np.array([[30.5, 20.5], [30.5, 19.5], [30.5, 21.5]])
    _, ok = sample_range(img, pts, max_slope_deg=80.0)
    assert ok.tolist() == [False, True, True]
    # the segment across the step rises atan(~8 / 0.7) ~ 85 deg: an 86 deg bound lets it pass
    dz = img[21, 30, 2] - img[20, 30, 2]
    assert 84.5 < np.degrees(np.arctan2(abs(dz), 0.7)) < 85.5
    assert sample_range(img, pts, max_slope_deg=86.0)[1].all()
    assert sample_range(img, pts)[1].all()  # no check: the paper's bilinear rule


def test_the_step_rule_does_not_depend_on_resolution():
    # a 70 deg ramp sampled at 0.5 mm and at 3 mm pixels is a surface, never a step
    for pitch in (0.5, 3.0):
        y, x = np.mgrid[0:20, 0:20] * pitch
        img = np.stack([x, y, 1000.0 + np.tan(np.radians(70.0)) * x], axis=-1)
        pts = np.random.default_rng(5).uniform(0, 19, (300, 2))
        v, ok = sample_range(img, pts, max_slope_deg=80.0)
        assert ok.all()
        assert not sample_range(img, pts, max_slope_deg=60.0)[1].any()


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"min_weight": 0.0}, "min_weight: expected a share in \\(0, 1\\]"),
        ({"min_weight": 1.5}, "min_weight"),
        ({"max_slope_deg": 0.0}, "max_slope_deg: expected an angle in \\(0, 90\\) degrees"),
        ({"max_slope_deg": 90.0}, "max_slope_deg"),
    ],
)
def test_sampling_rules_bad_input(xyz, kw, match):
    with pytest.raises(InputError, match=match):
        sample_range(xyz, np.array([[3.0, 3.0]]), source="s01/car", **kw)


def _grid_mesh(z):
    """A (ny, nx) grid 4 mm apart at depth z (mm, scanner at the origin) and its triangles."""
    ny, nx = z.shape
    y, x = (np.mgrid[0:ny, 0:nx] - [[[ny / 2]], [[nx / 2]]]) * 4.0
    i = np.arange(ny * nx).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return np.stack([x.ravel(), y.ravel(), z.ravel()], 1), faces


def test_behind_steps_flags_the_far_side_of_a_depth_step_only():
    # rows 0-5 a chin at 1000 mm, rows 6-9 the neck 40 mm behind: the first neck row is joined to
    # the chin by steep edges and is flagged; the chin and the rest of the neck are not
    z = np.full((10, 12), 1000.0)
    z[6:] = 1040.0
    v, faces = _grid_mesh(z)
    flagged = behind_steps(v, faces, 80.0).reshape(10, 12)
    assert flagged[6].all() and not flagged[:6].any() and not flagged[7:].any()
    # the same step in a scanner frame looking down -z (FRGC): "far" is still the neck
    v_neg = v * [1, 1, -1]
    np.testing.assert_array_equal(behind_steps(v_neg, faces, 80.0), flagged.ravel())
    # invalid (NaN) vertices are skipped, never flagged
    v[6 * 12 : 6 * 12 + 12] = np.nan
    assert not behind_steps(v, faces, 80.0)[6 * 12 : 7 * 12].any()


def test_behind_steps_keeps_a_steep_continuous_surface():
    # a 70 deg ramp (steep cheek beside the nose), 4 mm vertex spacing: no step
    z = 1000.0 + np.tan(np.radians(70.0)) * 4.0 * np.arange(12)[None, :].repeat(10, 0)
    v, faces = _grid_mesh(z)
    assert not behind_steps(v, faces, 80.0).any()
    assert behind_steps(v, faces, 60.0).any()


def test_points_outside_or_not_finite_are_invalid(xyz):
    pts = np.array([[-0.01, 5], [W - 0.99, 5], [5, -1e-9], [5, H - 0.5], [np.nan, 3], [3, np.inf]])
    v, valid = sample_range(xyz, pts)
    assert not valid.any() and np.isnan(v).all()


def test_bilinear_error_on_a_sphere_is_within_the_analytic_bound():
    # Orthographic scan of a sphere z = sqrt(R^2 - x^2 - y^2), pixel pitch p: bilinear
    # interpolation of a smooth surface is off by at most p^2 / 8 (|z_xx| + |z_yy|) + ... ; within
    # 0.7 R of the axis |z_xx| <= R^2 / (R^2 - r^2)^1.5 <= 2.75 / R.
    p, r_mm = 0.7, 80.0
    y, x = (np.mgrid[0:240, 0:240] - 119.5) * p
    z = np.sqrt(np.clip(r_mm**2 - x**2 - y**2, 0, None))
    xyz = np.stack([x, y, z], axis=-1)
    rng = np.random.default_rng(4)
    ang, rad = rng.uniform(0, 2 * np.pi, 3000), 0.7 * r_mm * np.sqrt(rng.uniform(0, 1, 3000))
    pts = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)]) / p + 119.5
    v, valid = sample_range(xyz, pts)
    assert valid.all()
    dist = np.abs(np.linalg.norm(v, axis=1) - r_mm)
    assert dist.max() < p**2 / 8 * 2 * 2.75 / r_mm  # 0.0067 mm, far below the 0.3 mm goal


def test_texture_uv_maps_pixel_centres_and_image_corners():
    pts = np.array([[0.0, 0.0], [W - 1, H - 1], [-0.5, -0.5], [W - 0.5, H - 0.5]])
    np.testing.assert_allclose(
        texture_uv(pts, W, H),
        [[0.5 / W, 0.5 / H], [1 - 0.5 / W, 1 - 0.5 / H], [0, 0], [1, 1]],
        atol=1e-15,
    )
    # beyond the image's edge (a template reaching past a face that fills its image): the
    # edge's texel, so that the exports' texture coordinates stay in [0, 1]
    beyond = np.array([[-13.0, 20.0], [W + 4.0, -30.0], [10.0, H + 0.1]])
    np.testing.assert_allclose(
        texture_uv(beyond, W, H), [[0, 20.5 / H], [1, 0], [10.5 / W, 1]], atol=1e-15
    )


def test_fold_check_counts_flipped_triangles(template):
    pts = np.asarray(template.vertices, dtype=float)
    assert not check_no_folds(pts, template.faces, "s/t").any()
    mirrored = pts * [-1.0, 1.0]
    with pytest.raises(InputError, match="^s/t: landmarks fold the template: 800 of 800 "):
        check_no_folds(mirrored, template.faces, "s/t")
    bent = pts.copy()
    bent[template.named["nose_tip"]] = bent[template.named["nose_bridge"]]  # a few flip
    with pytest.raises(InputError, match=r"s/t: landmarks fold the template: \d+ of 800"):
        check_no_folds(bent, template.faces, "s/t")
    folded = check_no_folds(bent, template.faces, "s/t", max_fraction=0.05)
    assert 0 < folded.sum() < 40


@pytest.mark.parametrize("levels", [0, 1, 2])
@pytest.mark.parametrize("fiducials", ["closed", "open"])
def test_fit_take_is_exact_when_the_landmarks_are_an_affine_image(template, xyz, levels, fiducials):
    lm = _landmarks(template)
    mesh = fit_take(template, lm, xyz, (W, H), fiducials, FitRules(levels=levels), "s/t")
    fine = subdivide_template(template, levels)
    expect2d = np.asarray([320.0, 230.0]) + 70.0 * fine.vertices
    np.testing.assert_allclose(mesh["points2d"], expect2d, atol=1e-9)
    assert mesh["valid"].all() and mesh["n_folded"] == 0
    np.testing.assert_allclose(mesh["vertices"], _on_plane(expect2d), rtol=0, atol=1e-9)
    np.testing.assert_allclose(mesh["uv"], (expect2d + 0.5) / [W, H], atol=1e-12)
    np.testing.assert_array_equal(mesh["faces"], fine.faces)
    assert len(mesh["faces"]) == 800 * 4**levels


def test_fitted_faces_face_the_scanner(template, xyz):
    # counter-clockwise as seen in the image => normals point back to the camera at the origin
    mesh = fit_take(template, _landmarks(template), xyz, (W, H), "closed", FitRules(), "s/t")
    tm = trimesh.Trimesh(mesh["vertices"], mesh["faces"], process=False)
    to_camera = -tm.triangles_center
    assert ((tm.face_normals * to_camera).sum(axis=1) > 0).all()


def test_fit_take_marks_vertices_over_holes_invalid(template, xyz):
    img = xyz.copy()
    img[200:260, 280:360] = np.nan  # a hole over the nose and mouth
    mesh = fit_take(template, _landmarks(template), img, (W, H), "closed", FitRules(), "s/t")
    p = mesh["points2d"]
    over_hole = (p[:, 0] > 279) & (p[:, 0] < 360) & (p[:, 1] > 199) & (p[:, 1] < 260)
    np.testing.assert_array_equal(mesh["valid"], ~over_hole)
    assert np.isnan(mesh["vertices"][over_hole]).all()


def test_fit_take_bad_input(template, xyz):
    lm = _landmarks(template)
    with pytest.raises(InputError, match=r"^s/t: landmarks: expected \(68, 2\), got \(68, 3\)"):
        fit_take(template, np.zeros((68, 3)), xyz, (W, H), source="s/t")
    nan = lm.copy()
    nan[45, 1] = np.nan
    with pytest.raises(InputError, match="^s/t: landmarks: point 46 .* not finite"):
        fit_take(template, nan, xyz, (W, H), source="s/t")
    with pytest.raises(InputError, match="^s/t: image_size: 640x400 .* range image is 640x480"):
        fit_take(template, lm, xyz, (W, 400), source="s/t")
    with pytest.raises(InputError, match=r"^s/t: xyz: expected \(H, W, 3\)"):
        fit_take(template, lm, xyz[..., :2], (W, H), source="s/t")
    with pytest.raises(InputError, match="^s/t: fiducial_set: unknown set 'wide'"):
        fit_take(template, lm, xyz, (W, H), "wide", source="s/t")
    with pytest.raises(InputError, match=r"^s/t: fiducial_set: iBUG points \[1\] are not template"):
        fit_take(template, lm, xyz, (W, H), [1, 9, 37, 46], source="s/t")
    out = lm.copy()
    out[8] = [320.0, 481.0]  # the chin below the image
    with pytest.raises(InputError, match=r"^s/t: fiducials: image point 0 \(iBUG 9\) .* outside"):
        fit_take(template, out, xyz, (W, H), source="s/t")
    same = lm.copy()
    same[:, 0] = 320.0  # all landmarks on one vertical line: the warp would collapse the template
    with pytest.raises(InputError, match=r"^s/t: fiducials: the image points all lie on one line"):
        fit_take(template, same, xyz, (W, H), source="s/t")
    same[:, 1] = 200.0  # all on one point
    with pytest.raises(InputError, match=r"^s/t: fiducials: the image points all coincide"):
        fit_take(template, same, xyz, (W, H), source="s/t")
    with pytest.raises(InputError, match="^config: template.subdivision_levels: .* got -1"):
        fit_take(template, lm, xyz, (W, H), rules=FitRules(levels=-1), source="s/t")
    sparse = np.full_like(xyz, np.nan)
    sparse[:150, :260] = xyz[:150, :260]  # range data over a small corner of the face only
    with pytest.raises(InputError, match=r"^s/t: only \d+\.\d% of the template's vertices"):
        fit_take(template, lm, sparse, (W, H), source="s/t")
    mirrored = lm * [-1.0, 1.0] + [640.0, 0.0]
    with pytest.raises(
        InputError, match=r"^s/t: landmarks fold the template: (\d+) of \1 warped triangles outside"
    ):
        fit_take(template, mirrored, xyz, (W, H), source="s/t")


def test_custom_fiducial_sets_by_ibug_number(template, xyz):
    lm = _landmarks(template)
    mesh = fit_take(template, lm, xyz, (W, H), [9, 28, 37, 46, 49, 55], FitRules(levels=0), "s/t")
    np.testing.assert_allclose(
        mesh["points2d"], [320.0, 230.0] + 70.0 * template.vertices, atol=1e-9
    )
