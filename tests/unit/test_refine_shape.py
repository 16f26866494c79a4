"""The shape-driven refinement (scan2morph.refine.shape): the curvature image against the
sphere's known curvature, and the refinement against known tangential motions of a surface
whose texture does not match the neutral's (the oracle)."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter, map_coordinates

from scan2morph.errors import InputError
from scan2morph.refine import Channel, RefineParams, SurfaceChannel, refine_channels
from scan2morph.refine.shape import ShapeParams, shape_image
from scan2morph.template import build_template, subdivide_template
from tests.support.configs import config_schema, repo_config

SHAPE = (420, 380)
MM_PER_PX = 0.7
SCALE, CENTRE = 90.0, np.array([190.0, 170.0])  # the template's px per unit and its centre


@pytest.fixture(scope="module")
def fine():
    return subdivide_template(build_template(), 1)


def _grid():
    return np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]].astype(np.float64)


def _surface(height):
    """(H, W, 3) points of a height field (mm towards the camera) seen from 1 m, mm."""
    yy, xx = _grid()
    return np.stack([(xx - 190) * MM_PER_PX, (yy - 210) * MM_PER_PX, 1000.0 - height], axis=-1)


def _bumps(seed):
    """A surface with shape: a dome and random bumps 1 mm high, about 6 mm across."""
    yy, xx = _grid()
    noise = gaussian_filter(np.random.default_rng(seed).standard_normal(SHAPE), 8.0)
    dome = 30.0 - 30.0 * (((xx - 190) / 400) ** 2 + ((yy - 210) / 400) ** 2)
    return dome + noise / noise.std()


def _texture(seed):
    rng = np.random.default_rng(seed)
    t = gaussian_filter(rng.standard_normal(SHAPE), 1.5)
    return 150.0 + 25.0 * t / t.std()


def _motion():
    """A smooth tangential motion up to 3 px (as the textured refinement's test)."""
    yy, xx = _grid()
    ux = 3.0 * np.exp(-(((xx - 190) / 70) ** 2 + ((yy - 260) / 60) ** 2))
    uy = 2.0 * np.exp(-(((xx - 230) / 60) ** 2 + ((yy - 200) / 70) ** 2))
    return ux, uy


def _warp(image, dx, dy):
    yy, xx = _grid()
    return map_coordinates(image, [yy + dy, xx + dx], order=3, mode="nearest")


def _fit(s):
    return np.asarray(s) * SCALE + CENTRE


def _half_fit(s):
    """:func:`_fit` on every second pixel of the grid."""
    return np.asarray(s) * (SCALE / 2) + CENTRE / 2


def _rms(points, true, inner):
    return float(np.sqrt(np.mean(np.sum((points - true)[inner] ** 2, axis=1))))


def test_the_shape_image_is_the_mean_curvature_of_a_sphere():
    """A sphere of radius 80 mm facing the camera: 1/80 per mm = 12.5 per m, positive (it
    bulges towards the camera); the same under a rigid motion of the camera."""
    yy, xx = _grid()
    r2 = ((xx - 190) ** 2 + (yy - 210) ** 2) * MM_PER_PX**2
    height = np.sqrt(np.maximum(80.0**2 - r2, 0.0))
    xyz = _surface(np.where(r2 < 70.0**2, height, np.nan))
    h = shape_image(xyz, 2.0)
    inner = r2 < 50.0**2
    assert np.isnan(h[~np.isfinite(xyz).all(axis=-1)]).all()
    np.testing.assert_allclose(np.median(h[inner]), 12.5, rtol=0.03)
    assert np.percentile(np.abs(h[inner] - 12.5), 95) < 0.6
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    moved = shape_image(xyz @ turn.T + np.array([5.0, -3.0, 20.0]), 2.0)
    assert np.nanmax(np.abs(moved - h)) < 0.3
    # a frame whose origin lies behind the surface (a mesh scan's own frame): the same sign
    for depth_mm in (-1000.0, -100.0, 0.0, 40.0, 500.0):
        shifted = shape_image(xyz - np.array([0.0, 0.0, xyz[..., 2][inner].mean() + depth_mm]), 2.0)
        assert np.nanmax(np.abs(shifted - h)) < 0.3, depth_mm


def test_a_range_image_without_shape_is_refused():
    with pytest.raises(InputError, match=r"xyz: expected an \(H, W, 3\) range image"):
        shape_image(np.zeros((4, 4)), 2.0, "s/neutral")
    with pytest.raises(InputError, match="no two neighbouring pixels with data"):
        shape_image(np.full((4, 4, 3), np.nan), 2.0, "s/neutral")


@pytest.mark.parametrize(
    ("key", "value", "problem"),
    [
        ("sigma_mm", 0.0, "sigma_mm: expected a number > 0"),
        ("noise", "x", "noise: expected a number"),
        ("use", 1, "use: expected true or false"),
        ("min_confident_share", 1.5, "min_confident_share: expected a share 0..1"),
    ],
)
def test_bad_shape_settings_are_refused(key, value, problem):
    with pytest.raises(InputError, match=problem):
        ShapeParams(**{key: value})


def test_the_shape_follows_a_tangential_motion_the_texture_cannot(fine):
    """The take's surface is the neutral's with its bumps carried by a known tangential motion,
    under an unrelated texture; the fit slid by the motion. The texture alone finds nothing (the
    template fit stays); the curvature image recovers the motion (with the unrelated texture
    added, its false matches outweigh the shape: ``refine.shape.texture`` false)."""
    ux, uy = _motion()
    height = _bumps(7)
    neutral_xyz = _surface(height)
    take_xyz = _surface(_warp(height, -ux, -uy))  # the bump at p is at p + u(p)
    pn = _fit(fine.vertices)
    at = [map_coordinates(u, [pn[:, 1], pn[:, 0]], order=1) for u in (ux, uy)]
    true = pn + np.column_stack(at)
    _, anchors = build_template().fiducial_set("closed")
    params, prm = RefineParams(), ShapeParams()
    texture = Channel(_texture(4), _texture(5), 3.0, 2.0, 0.25)
    shape = Channel(
        shape_image(neutral_xyz, prm.sigma_mm),
        shape_image(take_xyz, prm.sigma_mm),
        prm.high_pass_px,
        prm.noise,
        prm.precision_px,
    )
    inner = (np.abs(pn - CENTRE) < np.array([150, 180])).all(axis=1)
    maps = (_fit, _fit)
    by_texture, t_report = refine_channels(
        fine.vertices, fine.faces, maps, [texture], anchors, params
    )
    by_shape, s_report = refine_channels(fine.vertices, fine.faces, maps, [shape], anchors, params)
    fit_err, texture_err = _rms(pn, true, inner), _rms(by_texture, true, inner)
    shape_err = _rms(by_shape, true, inner)
    print("rms px: fit", fit_err, "texture", texture_err, "shape", shape_err)
    assert fit_err > 1.0 and texture_err > 0.9 * fit_err
    assert t_report["confident_share"] < 0.1
    assert shape_err < 0.35 * fit_err, (fit_err, shape_err)
    assert s_report["confident_share"] > ShapeParams().min_confident_share


def test_the_confidence_has_one_scale_whatever_the_channels(fine):
    """A lone channel whose precision is not the flow's has its confidence on the scale of
    several channels (its weight times ``flow_precision_px^2``): adding a channel that measures
    nothing (a flat image) changes neither the points nor the confidence. (An equality: on
    every second pixel of the bumps, 1.4 mm per px, the fit mapped at half the scale.)"""
    height = _bumps(7)
    image = shape_image(_surface(height)[::2, ::2], ShapeParams().sigma_mm)
    prm, params = ShapeParams(), RefineParams()
    shape = Channel(image, image, prm.high_pass_px, prm.noise, prm.precision_px)
    flat = Channel(np.ones_like(image), np.ones_like(image), 3.0, 2.0, prm.precision_px)
    _, anchors = build_template().fiducial_set("closed")
    maps = (_half_fit, _half_fit)
    one = refine_channels(fine.vertices, fine.faces, maps, [shape], anchors, params)
    two = refine_channels(fine.vertices, fine.faces, maps, [shape, flat], anchors, params)
    np.testing.assert_allclose(one[0], two[0], atol=1e-9)
    np.testing.assert_allclose(one[1]["confidence"], two[1]["confidence"], atol=1e-12)
    assert prm.precision_px != params.flow_precision_px
    assert 0.0 < np.max(one[1]["confidence"]) <= 1.0


def test_the_still_skin_undoes_a_fit_that_slid_on_a_smooth_surface(fine):
    """Neither the neutral nor the take moved, but the take's fit slid by a known field over a
    smooth dome without features: the curvature sees nothing; the still skin's measurement
    (each neutral point found on the take's surface) puts the vertices back."""
    ux, uy = _motion()
    yy, xx = _grid()
    dome = 30.0 - 30.0 * (((xx - 190) / 400) ** 2 + ((yy - 210) / 400) ** 2)
    xyz = _surface(dome)
    pn = _fit(fine.vertices)

    def slid(s):
        p = _fit(s)
        return p + np.column_stack(
            [map_coordinates(u, [p[:, 1], p[:, 0]], order=1) for u in (ux, uy)]
        )

    _, anchors = build_template().fiducial_set("closed")
    params, prm = RefineParams(), ShapeParams()
    image = shape_image(xyz, prm.sigma_mm)
    shape = Channel(image, image, prm.high_pass_px, prm.noise, prm.precision_px)
    surface = SurfaceChannel(xyz, xyz, prm.surface_tolerance_mm, prm.surface_precision_px)
    inner = (np.abs(pn - CENTRE) < np.array([150, 180])).all(axis=1)
    maps = (_fit, slid)
    alone, _ = refine_channels(fine.vertices, fine.faces, maps, [shape], anchors, params)
    both, report = refine_channels(
        fine.vertices, fine.faces, maps, [shape, surface], anchors, params
    )
    fit_err, alone_err, both_err = (_rms(p, pn, inner) for p in (slid(fine.vertices), alone, both))
    print("rms px: fit", fit_err, "shape alone", alone_err, "with the still skin", both_err)
    assert fit_err > 1.0 and alone_err > 0.8 * fit_err
    assert both_err < 0.2 * fit_err, (fit_err, both_err)
    assert report["confident_share"] > 0.8


def test_the_shape_defaults_agree_in_config_schema_and_library():
    """config/config.yaml's refine.shape, the schema's defaults and ShapeParams' are one set."""
    import dataclasses

    config = repo_config()["refine"]["shape"]
    schema = config_schema()
    spec = schema["properties"]["refine"]["properties"]["shape"]["properties"]
    library = ShapeParams()
    assert set(config) == set(spec) == {f.name for f in dataclasses.fields(ShapeParams)}
    for name in config:
        assert config[name] == getattr(library, name) == spec[name]["default"], name


def test_a_bad_shape_setting_in_the_config_is_named_by_its_key():

    from scan2morph.stages import refine

    config = repo_config()
    config["refine"]["shape"]["sigma_mm"] = -1.0
    with pytest.raises(InputError, match=r"refine\.shape: sigma_mm: expected a number > 0"):
        refine.Params.from_config(config)


def test_a_degenerate_surface_has_no_shape_and_no_warning():
    """Points along a line (every row the same: no surface) give NaN everywhere, quietly
    (warnings are errors here), and the still skin measures nothing on them."""
    from scan2morph.refine.shape import surface_flow

    line = np.zeros((20, 20, 3))
    line[..., 0] = np.arange(20.0)[None]
    line[..., 2] = 1000.0
    assert np.isnan(shape_image(line, 1.0)).all()
    grid = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), axis=-1)
    flow, conf = surface_flow(line, line, grid, 0.2)
    assert (flow == 0).all() and (conf == 0).all()
