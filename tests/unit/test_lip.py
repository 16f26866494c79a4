"""The upper-lip prior (scan2morph.refine.lip) and the lip regions of the template
(template.regions.lip), on an analytic lip rendered by ray casting with a pinhole camera (the
oracle): a lip that rolls about its vermilion border keeps its length, so where each of its
skin points went is known."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d, map_coordinates

from scan2morph.errors import InputError
from scan2morph.open3d_light import open3d
from scan2morph.refine.lip import (
    NO_BORDER,
    NO_SURFACE,
    TOO_FAR,
    LipImages,
    LipParams,
    LipPrior,
    lip_prior,
    redness,
    vermilion_edge,
)
from scan2morph.template import build_template, subdivide_template
from scan2morph.template.regions import Lip, inner_lip_midline, lip

o3d = open3d()  # open3d without its web viewer, as the library imports it

W, H, F = 240, 200, 1500.0
K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
DISTANCE = 600.0  # mm, camera to the skin's plane
LIP_MM = 8.0  # the lip's length from the border to the slit, along its surface
SKIN = np.array([0.80, 0.60, 0.50])
LIP = np.array([0.70, 0.33, 0.32])
COLUMNS = np.linspace(-8.0, 8.0, 7)  # mm: the template's lip columns
ROWS = np.array([-2.0, 0.0, 4.0, LIP_MM])  # material length from the border: skin to slit


def _material(x, a, angle_deg, scale=1.0):
    """Camera-frame points (n, 3) of the skin at material (x, a), mm: ``a`` is the length from
    the border along the surface (negative: the skin above it, a plane); the lip below it is a
    flat strip tilted towards the camera by ``angle_deg`` (it rolls out about the border),
    shortened to ``scale`` of its length."""
    t = np.radians(angle_deg)
    lip = scale * np.clip(a, 0.0, None)
    y = np.minimum(a, 0.0) + lip * np.cos(t)
    return np.stack([x, y, DISTANCE - lip * np.sin(t)], axis=-1)


def _step(a, centre, width=1.0):
    s = np.clip((a - centre) / width + 0.5, 0.0, 1.0)
    return s * s * (3 - 2 * s)


def _albedo(a, two_step=False):
    """The skin's colour at material length ``a`` (n, 3): red lips below the border (a 1 mm
    smooth step), or with ``two_step`` a border in two steps: a larger one 0.6 mm onto the skin
    and a smaller one 0.8 mm onto the lip (a border whose steepest fall depends on the view)."""
    if not two_step:
        return SKIN + _step(a, 0.0)[:, None] * (LIP - SKIN)
    share = 0.6 * _step(a, -0.6) + 0.4 * _step(a, 0.8)
    return SKIN + share[:, None] * (LIP - SKIN)


def _render(
    angle_deg, gain=1.0, end_mm=LIP_MM + 2.0, grey=False, two_step=False, scale=1.0, gap=None
):
    """(xyz (H, W, 3) mm, colour (H, W, 3) uint8) of the rolled lip (shortened to ``scale``,
    the strip's triangles between the material lengths ``gap`` (a, b) left out); NaN where rays
    miss."""
    xs, as_ = np.meshgrid(np.arange(-20.0, 20.01, 0.25), np.arange(-12.0, end_mm + 1e-6, 0.25))
    v = _material(xs.ravel(), as_.ravel(), angle_deg, scale)
    nx = xs.shape[1]
    i = (np.arange(nx - 1)[None, :] + nx * np.arange(xs.shape[0] - 1)[:, None]).ravel()
    faces = np.concatenate([np.c_[i, i + 1, i + nx + 1], np.c_[i, i + nx + 1, i + nx]])
    if gap is not None:
        a = as_.ravel()[faces]
        faces = faces[(a.max(axis=1) <= gap[0]) | (a.min(axis=1) >= gap[1])]
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32))
    )
    ys, xs_ = np.mgrid[0:H, 0:W].astype(np.float64)
    d = np.stack([(xs_ - K[0, 2]) / F, (ys - K[1, 2]) / F, np.ones_like(xs_)], axis=-1)
    rays = np.concatenate([np.zeros_like(d), d], axis=-1).reshape(-1, 6).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))
    t = hit["t_hit"].numpy().astype(np.float64)
    ok = np.isfinite(t)
    xyz = np.where(ok[:, None], t[:, None] * d.reshape(-1, 3), np.nan).reshape(H, W, 3)
    f = faces[np.where(ok, hit["primitive_ids"].numpy(), 0)]
    uv = hit["primitive_uvs"].numpy().astype(np.float64)
    bary = np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=-1)
    a = np.einsum("nk,nk->n", as_.ravel()[f], bary)
    colour = np.where(ok[:, None], gain * 255 * _albedo(a, two_step), 0.0)
    if grey:
        colour = colour.mean(axis=1, keepdims=True).repeat(3, axis=1)
    return xyz, np.clip(colour, 0, 255).astype(np.uint8).reshape(H, W, 3)


def _project(points):
    p = points @ K.T
    return p[:, :2] / p[:, 2:]


def _template_lip():
    """A small template over the lip: rows (skin, border, body, slit) x COLUMNS, its Lip, and
    the template coordinates (mm / 10)."""
    xs, as_ = np.meshgrid(COLUMNS, ROWS)
    nx = len(COLUMNS)
    i = (np.arange(nx - 1)[None, :] + nx * np.arange(len(ROWS) - 1)[:, None]).ravel()
    faces = np.concatenate([np.c_[i, i + 1, i + nx + 1], np.c_[i, i + nx + 1, i + nx]])
    rows = np.arange(len(ROWS) * nx).reshape(len(ROWS), nx)
    region = Lip(inner=rows[3], outline=rows[1], between=rows[2])
    return xs.ravel(), as_.ravel(), faces, region, np.c_[xs.ravel(), as_.ravel()] / 10.0


def _scene(angle_deg=55.0, slide_px=(0.0, 0.0, 2.0, 4.0), two_step=False, scale=1.0, **take_render):
    """The neutral (lip tilted 15 degrees) and a take (``angle_deg``), the template's points in
    both, the take's true points and a flow slid along the lip by ``slide_px`` per row."""
    x, a, faces, region, v2 = _template_lip()
    neutral = _render(15.0, two_step=two_step)
    take = _render(angle_deg, two_step=two_step, scale=scale, **take_render)
    pn = _project(_material(x, a, 15.0))
    true = _project(_material(x, a, angle_deg, scale))
    slide = np.repeat(np.asarray(slide_px), len(COLUMNS))
    flow = true + slide[:, None] * np.array([0.0, -1.0])  # towards the border: the lip too short
    return dict(neutral=neutral, take=take, pn=pn, true=true, flow=flow, faces=faces,
                region=region, v2=v2)  # fmt: skip


def _prior(s, params=None, flow=None):
    images = LipImages(s["neutral"][1], s["neutral"][0], s["take"][1], s["take"][0])
    return lip_prior(
        s["region"], s["v2"], s["pn"], s["flow"] if flow is None else flow, images, s["faces"],
        LipParams() if params is None else params,
    )  # fmt: skip


def _material_length(points_y, angle_deg):
    """The material length from the border (mm) of image rows on the middle column."""
    a = np.linspace(-3.0, 12.0, 150001)
    rows = _project(_material(np.zeros_like(a), a, angle_deg))[:, 1]
    return np.interp(points_y, rows, a)


def test_the_prior_puts_a_rolled_lip_where_its_skin_went():
    """A lip that rolls out from 15 to 55 degrees about its border (its image height shrinks
    by 40%) under a 20% dimmer light; a flow that left its slit 4 px and its body 2 px short:
    held to the neutral's length (``stretch`` 0), the prior places every lip vertex within a
    third of a pixel of its skin point."""
    s = _scene(gain=0.8)
    prior = _prior(s, LipParams(stretch=0.0))
    assert prior.used, prior.problem
    region = s["region"]
    lip_vertices = region.vertices
    assert prior.measured == len(lip_vertices) == prior.vertices
    err = np.linalg.norm(prior.points[lip_vertices] - s["true"][lip_vertices], axis=1)
    before = np.linalg.norm(s["flow"][lip_vertices] - s["true"][lip_vertices], axis=1)
    print(f"\nlip prior: {before.max():.2f} px -> {err.max():.3f} px (max over the lip)")
    assert before.max() > 3.9
    assert err.max() < 0.33  # measured 0.1-0.2 px: the border's sampling, 0.2 px steps
    np.testing.assert_allclose(prior.weight[lip_vertices], 1.0)
    assert 0.05 < prior.contrast < 0.2  # redness: skin 0.42, lip 0.49 (a 1 mm step)
    # with the default stretch (a strain of 10%, plus 0.1 mm) the slit, 34% short, goes to the
    # nearest length allowed: 90% of the lip's length, give or take the border's sampling
    nearest = _prior(s)
    middle = region.inner[len(COLUMNS) // 2]
    length = _material_length(nearest.points[middle, 1], 55.0)
    assert 0.85 * LIP_MM < length < 0.92 * LIP_MM, length  # measured 7.21 mm
    # the lip has a place, and nothing else
    placed = np.isfinite(prior.points).all(axis=1)
    np.testing.assert_array_equal(np.flatnonzero(placed), lip_vertices)


def test_a_flow_within_the_lips_stretch_is_kept():
    """The lip's length may change by ``stretch``: a flow that is right (or within it) stays;
    with ``stretch`` 0 it is held to the neutral's length exactly."""
    s = _scene(slide_px=(0.0, 0.0, 0.0, 0.0))
    prior = _prior(s)
    assert prior.used
    lip_vertices = s["region"].vertices
    np.testing.assert_allclose(prior.points[lip_vertices], s["flow"][lip_vertices], atol=1e-6)
    # a 0.8 px slide of the slit is 0.56 mm (7% of the 8 mm lip) in this view: within 10%
    small = _scene(slide_px=(0.0, 0.0, 0.4, 0.8))
    kept = _prior(small)
    inner = s["region"].inner
    np.testing.assert_allclose(kept.points[inner], small["flow"][inner], atol=1e-6)
    held = _prior(small, LipParams(stretch=0.0))
    # the colour edge sits 0.13 mm apart in the two views (0.2-0.3 px)
    assert np.linalg.norm(held.points[inner] - small["true"][inner], axis=1).max() < 0.4


def test_the_prior_needs_a_red_lip_in_both_images():
    """Grey images (a sprayed face, a grey camera) show no vermilion border: not used."""
    s = _scene(grey=True)
    prior = _prior(s)
    assert not prior.used and f"{NO_BORDER}: 21" in prior.problem, prior.problem
    assert prior.measured == 0 and np.isnan(prior.points).all() and not prior.weight.any()


def test_the_prior_drops_what_the_takes_surface_cannot_carry():
    """The take's surface ends 5 mm below the border (the lip rolled in): the slit's length
    cannot be walked there, so the slit vertices are not placed, the body's are, and the slit
    follows harmonically; with ``min_share`` above the share placed the prior is refused."""
    s = _scene(end_mm=5.0)
    prior = _prior(s)
    region = s["region"]
    assert prior.used
    placed = np.flatnonzero(prior.weight == 1.0)
    np.testing.assert_array_equal(placed, np.setdiff1d(region.vertices, region.inner))
    assert np.isfinite(prior.points[region.inner]).all()  # they follow the body
    refused = _prior(s, LipParams(min_share=0.9))
    assert not refused.used and "at least 90%" in refused.problem
    assert f"{NO_SURFACE}: 7" in refused.problem, refused.problem


def test_the_prior_moves_no_vertex_by_more_than_max_shift():
    """The body's vertices, 2 px off in a lip 7.6 px high (as the flow has it), need a shift of
    0.26 lip heights: with ``max_shift`` 0.15 they are not placed (nor the slit's, 4 px off),
    with 0.3 they are."""
    s = _scene()
    region = s["region"]
    tight = _prior(s, LipParams(max_shift=0.15, min_share=0.9))
    assert not tight.used and tight.measured == len(region.outline)
    assert f"{TOO_FAR}: " in tight.problem, tight.problem
    loose = _prior(s, LipParams(max_shift=0.3, min_share=0.1))
    placed = np.flatnonzero(loose.weight == 1.0)
    assert np.isin(region.between, placed).all() and not np.isin(region.inner, placed).any()


def test_a_lip_that_shortens_keeps_its_share_of_its_length():
    """The lower lip's case: the lip rounds and shortens to 80% of its length, and the mouth is
    open (the take's surface ends at the slit). Held to its length the slit cannot be placed
    (the surface ends first); with ``shrink`` its vertices keep their share of the length
    between the border and where the surface ends, within 0.8 px of their skin points (the
    surface's end is found to about half a pixel: the range is sampled where half of a
    point's bilinear weight has data). A closed mouth (the surface resumes past a 2 mm crease) keeps the flow's answer."""
    s = _scene(scale=0.8, end_mm=LIP_MM, slide_px=(0.0, 0.0, 1.0, 2.0))
    region = s["region"]
    held = _prior(s, LipParams(stretch=0.0, min_share=0.1))
    assert not np.isin(region.inner, np.flatnonzero(held.weight == 1.0)).any()
    shrunk = _prior(s, LipParams(stretch=0.0, shrink=0.4))
    assert shrunk.used and shrunk.measured == len(region.vertices), shrunk.problem
    err = np.linalg.norm(shrunk.points[region.vertices] - s["true"][region.vertices], axis=1)
    before = np.linalg.norm(s["flow"] - s["true"], axis=1)[region.inner]
    print(f"\nshortened lip: slit {before.max():.2f} px -> {err.max():.3f} px (max over the lip)")
    assert err.max() < 0.8, err.max()  # measured 0.70 (the slit), 0.64 (the body)
    # a closed mouth: a crease, then the other lip
    closed = _scene(gap=(LIP_MM, LIP_MM + 2.0), end_mm=LIP_MM + 5.0)
    kept = _prior(closed, LipParams(stretch=0.0, shrink=0.4))
    inner = closed["region"].inner
    np.testing.assert_allclose(kept.points[inner], closed["flow"][inner], atol=1e-9)


def test_apply_replaces_the_lip_and_raises_the_confidence():
    s = _scene()
    prior = _prior(s)
    n = len(s["pn"])
    confidence = np.full(n, 0.5)
    points, conf = prior.apply(s["flow"], confidence)
    has = np.isfinite(prior.points).all(axis=1)
    np.testing.assert_array_equal(points[has], prior.points[has])
    np.testing.assert_array_equal(points[~has], s["flow"][~has])
    np.testing.assert_allclose(conf, 0.5 + np.where(has, prior.weight, 0.0) * 0.5)
    off = LipPrior(np.full((n, 2), np.nan), np.zeros(n), 0, 0, 0.0, False, "off")
    np.testing.assert_array_equal(off.apply(s["flow"], confidence)[0], s["flow"])


def test_vermilion_edge_and_redness():
    """The steepest fall of a smooth step is its middle; the contrast is the two sides'
    means' difference."""
    t = np.linspace(-0.2, 1.6, 181)
    red = 0.42 + 0.08 / (1 + np.exp((t - 1.1) / 0.05))
    edge, contrast = vermilion_edge(red, t, 1.0, 0.5)
    assert abs(edge - 1.1) < 0.011
    lip, skin = red[(t >= 0) & (t < edge)], red[t > edge]
    assert contrast == pytest.approx(lip.mean() - skin.mean())
    assert vermilion_edge(red, t, 3.0, 0.5) is None  # nothing in the window
    c = np.array([[[200, 100, 100], [0, 0, 0]]], dtype=np.uint8)
    r = redness(c)
    assert r[0, 0] == pytest.approx(0.5) and np.isnan(r[0, 1])
    with pytest.raises(InputError, match=r"\(H, W, 3\)"):
        redness(np.zeros((4, 4)))


def test_the_templates_lips():
    """The default template's upper and lower lip: slit vertices on the mouth's boundary on
    their side of the inner-lip midline, the border's vertices on the vermilion border, bodies
    between the two; each slit vertex's column runs straight across the lip
    (its border point at its own template x)."""
    template = build_template()
    for levels in (0, 1, 2):
        fine = subdivide_template(template, levels)
        v = fine.vertices
        mid = inner_lip_midline(template.ibug_xy[60:68])
        offset = v[:, 1] - np.interp(v[:, 0], mid[:, 0], mid[:, 1])
        for side, sign, rows in (
            ("upper", -1, slice(48, 55)),
            ("lower", 1, [54, 55, 56, 57, 58, 59, 48]),
        ):
            region = lip(fine, side)
            assert len(region.inner) >= 3 and len(region.outline) >= 3
            assert np.isin(region.inner, fine.mouth_boundary).all()
            assert (sign * offset[region.inner] > 0).all()
            # the body lies between the slit and the border
            border = template.ibug_xy[rows]
            order = np.argsort(border[:, 0])
            line = np.interp(v[:, 0], border[order, 0], border[order, 1])
            assert (sign * offset[region.between] > 0).all()
            assert (sign * (line[region.between] - v[region.between, 1]) > 0).all()
            np.testing.assert_allclose(v[region.outline, 1], line[region.outline], atol=0.04)
            assert np.isin(region.outline, region.vertices).all()
            cols = region.columns(v)
            assert cols.shape == region.vertices.shape and cols.max() < len(region.inner)
            # template coordinates in, the border's point at each slit vertex's x out
            above = region.border_points(v, v)
            xo = v[region.outline, 0]
            within = (v[region.inner, 0] >= xo.min()) & (v[region.inner, 0] <= xo.max())
            assert within.sum() >= len(within) - 2  # the outermost slit vertices of level 2
            np.testing.assert_allclose(above[within, 0], v[region.inner[within], 0], atol=1e-9)
            np.testing.assert_allclose(above[:, 1], line[region.inner], atol=0.04)
    with pytest.raises(InputError, match="lip side 'middle'"):
        lip(template, "middle")


def test_register_recovers_a_known_shift():
    """The redness registration: a smooth border shifted by a known, off-grid length (either
    sign) is recovered to a thousandth of a millimetre; a best match at the edge of the shifts
    allowed is no match."""
    from scan2morph.refine.lip_profile import register_redness as _register

    arc = np.linspace(-4.0, 4.0, 401)
    red = 0.42 + 0.09 * (1.0 - _step(arc, 0.0, 1.5))
    wide = np.linspace(-8.0, 8.0, 801)
    for true in (0.123, -0.537, 1.01):
        moved = 0.42 + 0.09 * (1.0 - _step(wide, true, 1.5))
        assert _register(arc, red, wide, moved, 2.0) == pytest.approx(true, abs=1e-3)
    moved = 0.42 + 0.09 * (1.0 - _step(wide, 3.0, 1.5))
    assert _register(arc, red, wide, moved, 2.0) is None  # the best lies beyond 2 mm


def test_a_border_whose_steepest_fall_moves_is_registered():
    """A border in two steps, the larger on the skin, the smaller on the lip: seen from the
    front its steepest fall is the skin's step, on the rolled lip (foreshortened 43%) the lip's
    step, 1.4 mm of skin apart. The registration matches the two, and the prior still places
    every lip vertex within a third of a pixel (held to the neutral's length)."""
    s = _scene(two_step=True)
    middle = len(COLUMNS) // 2
    region = s["region"]
    edges = []
    for (_, colour), points, angle in (
        (s["neutral"], s["pn"], 15.0), (s["take"], s["true"], 55.0)
    ):  # fmt: skip
        top, bottom = points[region.outline[middle]], points[region.inner[middle]]
        t = np.linspace(-0.2, 1.6, 721)
        line = bottom + t[:, None] * (top - bottom)
        red = map_coordinates(redness(colour), [line[:, 1], line[:, 0]], order=1)
        edge, _ = vermilion_edge(gaussian_filter1d(red, 10.0)[40:-40], t[40:-40], 1.0, 0.5)
        edges.append(_material_length(bottom[1] + edge * (top[1] - bottom[1]), angle))
    assert abs(edges[0] - edges[1]) > 1.0, edges  # the steepest falls are on other skin
    prior = _prior(s, LipParams(stretch=0.0))
    assert prior.used and prior.measured == len(region.vertices), prior.problem
    err = np.linalg.norm(prior.points[region.vertices] - s["true"][region.vertices], axis=1)
    assert err.max() < 0.35, err.max()


def test_lip_params_and_prior_name_bad_input():
    for bad, match in (
        ({"min_contrast": 0.0}, "^LipParams: min_contrast: expected 0 < contrast < 1"),
        ({"search": 1.5}, "^LipParams: search"),
        ({"max_shift": -1}, "^LipParams: max_shift"),
        ({"max_shift": float("inf")}, "^LipParams: max_shift"),
        ({"min_share": 0}, "^LipParams: min_share"),
        ({"stretch": 1.0}, "^LipParams: stretch"),
        ({"stretch": "a"}, "^LipParams: stretch: expected a number"),
        ({"shrink": 1.0}, "^LipParams: shrink"),
        ({"shrink": None}, "^LipParams: shrink: expected a number"),
        ({"prior": "no"}, "^LipParams: prior: expected true or false"),
    ):
        with pytest.raises(InputError, match=match):
            LipParams(**bad)
    s = _scene()
    args = [
        s["region"], s["v2"], s["pn"], s["flow"], s["neutral"][1], s["neutral"][0],
        s["take"][1], s["take"][0], s["faces"], LipParams(),
    ]  # fmt: skip

    def bad(match, **change):
        names = ["lip", "v2", "pn", "pt", "cn", "xn", "ct", "xt", "faces", "params"]
        call = [change.get(k, a) for k, a in zip(names, args, strict=True)]
        with pytest.raises(InputError, match=match):
            lip_prior(*call[:4], LipImages(*call[4:8]), *call[8:], source="s/she")

    bad(r"s/she: lip prior: take_points has shape \(28, 3\)", pt=np.zeros((28, 3)))
    bad("12 neutral points, 28 take points and 28 template vertices", pn=s["pn"][:12])
    bad(
        r"the lip's inner \(7,\): expected indices below 12",
        v2=s["v2"][:12],
        pn=s["pn"][:12],
        pt=s["flow"][:12],
    )
    bad("take's range image has shape", xt=s["take"][0][:, :-1])
    bad(r"s/she: colour: expected an \(H, W, 3\)", ct=s["take"][1][..., 0])
    bad("faces", faces=s["faces"] + 30)
    far = Lip(np.array([40]), np.array([41]), np.array([], int))
    bad("the lip's inner", lip=far)
    empty = Lip(np.array([], int), np.array([7]), np.array([], int))
    bad("no slit or no border vertex", lip=empty)
    for red, t in ((np.zeros(5), np.arange(4.0)), (np.zeros((2, 3)), np.zeros((2, 3)))):
        with pytest.raises(InputError, match="1-D arrays of one length"):
            vermilion_edge(red, t, 1.0, 0.5)
    with pytest.raises(InputError, match="increasing"):
        vermilion_edge(np.zeros(4), np.array([0.0, 1.0, 1.0, 2.0]), 1.0, 0.5)
    assert vermilion_edge(np.array([0.5, np.nan]), np.array([0.0, 1.0]), 1.0, 0.5) is None


def test_redness_correlations_are_pearson_per_shift():
    """The registration's scores, all shifts at once, against numpy's Pearson correlation of
    each shift's overlap: equal to rounding; a shift covering under MIN_COVER of the profile,
    or one with a flat overlap, has no score."""
    from scan2morph.refine.lip_profile import MIN_COVER, _correlations

    rng = np.random.default_rng(3)
    n, shifts = 120, 9
    ref = rng.normal(size=n)
    moved = rng.normal(size=(shifts, n)) + 0.5 * ref
    inside = rng.random((shifts, n)) < 0.9
    inside[2, : int(0.5 * n)] = False  # under MIN_COVER
    inside[5] = True
    moved[5] = 0.5  # flat overlap (exactly: its mean is 0.5)
    got = _correlations(ref, moved, inside)
    for k in range(shifts):
        keep = inside[k]
        if keep.mean() < MIN_COVER or np.ptp(moved[k, keep]) == 0:
            assert np.isnan(got[k]), k
        else:
            want = np.corrcoef(ref[keep], moved[k, keep])[0, 1]
            assert got[k] == pytest.approx(want, abs=1e-14), k
    assert np.isnan(got[[2, 5]]).all() and np.isfinite(got).sum() == shifts - 2


def test_profile_smoothing_of_columns_is_each_columns_own():
    """A profile's surface points are smoothed all three coordinates at once: bit for bit each
    coordinate smoothed alone (gaps and ends normalised away, NaN kept), and a constant
    coordinate stays constant across a gap."""
    from scan2morph.refine.lip_profile import _smooth

    rng = np.random.default_rng(5)
    points = rng.normal(size=(57, 3)) * 100
    points[rng.random(57) < 0.2] = np.nan
    points[:, 2] = np.where(np.isnan(points[:, 2]), np.nan, 7.0)
    together = _smooth(points, 2.3)
    alone = np.stack([_smooth(points[:, k], 2.3) for k in range(3)], axis=1)
    np.testing.assert_array_equal(together, alone)
    assert np.array_equal(np.isnan(together), np.isnan(points))
    np.testing.assert_allclose(together[~np.isnan(points[:, 2]), 2], 7.0, rtol=1e-12)
