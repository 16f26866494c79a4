"""Dense correspondence refinement: the template fit corrected by image correlation of the skin.

The template fit carries 68 clicked points over the face by a thin-plate spline; between the
points the fitted vertices lie on the right surface but slide along it. This package measures
where each neutral skin point went in a take from the skin's own texture (as the modal-analysis
paper's image correlation does) and moves the take's vertices there, on the take's surface:

1. pull the neutral's and the take's colour images back into template space through their fits
   (:mod:`~scan2morph.refine.template_space`);
2. measure the displacement between the two with optical flow and a confidence, and fuse it into
   a smooth correction that keeps the fit where the skin shows nothing, with the fiducials as soft
   constraints (:mod:`~scan2morph.refine.flow`);
3. move each take vertex's pixel position by the correction and sample the take's range image
   there (the geometric term: every refined vertex lies on the measured surface).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from scan2morph.align.rigid import transform_points
from scan2morph.geometry import face_sides, lengths_2d
from scan2morph.refine.flow import aperture, fuse_across, fusion, measure_flow
from scan2morph.refine.memo import active, shared
from scan2morph.refine.shape import shape_image, surface_flow
from scan2morph.refine.template_space import TemplateGrid, pull_back, template_grid
from scan2morph.template.tps import TPS

__all__ = [
    "Channel",
    "SurfaceChannel",
    "RefineParams",
    "clipped_share",
    "compose_field",
    "grey",
    "neutral_grid",
    "pull_back_field",
    "refine_channels",
    "refine_points",
    "texture_channel",
]


@dataclass(frozen=True)
class RefineParams:
    """Parameters of the refinement (config section ``refine``).

    Attributes
    ----------
    iterations : int
        Measure-and-fuse rounds (each on the take image pulled back through the last map). Each
        round's correction is fused (smoothed, faded) on its own, so later rounds take up what
        the membrane left of the earlier ones.
    high_pass_px : float
        Scale of the high-pass that removes shading, px.
    noise_grey : float
        Image noise, grey levels: texture below it is not trusted.
    flow_precision_px : float
        Precision of one confident flow vector, px (its weight is ``1 / precision^2``).
    click_precision_px : float
        Precision of a clicked landmark, px (the fiducials' weight: both takes' clicks, so
        ``1 / (2 precision^2)``).
    smooth_px : float
        Membrane length: each round's correction varies over no less than about this, px.
    fade_px : float
        Where nothing is measured, a correction fades back to the fit over about this, px.
    max_fb_px, min_zncc : float
        The flow's consistency and correlation tests (:func:`~scan2morph.refine.flow.measure_flow`).
    flow_level : int
        Finest pyramid level of the flow's search: 0 the full resolution of the neutral's
        image, 1 half of it (:func:`~scan2morph.refine.flow.measure_flow`'s ``level``).
    margin_px : float
        Skin around the template's outline taken into the correlation, px (an outline vertex
        may have slid in from there).
    aperture_iterations : int
        Each round's fusion is solved again this many times with every vector trusted only
        across its image's texture (:func:`~scan2morph.refine.flow.aperture`; the component
        along an edge taken from the last solution): a fixed-point iteration towards the
        fusion with each vector's own 2 x 2 weight, on the same system. 0: every vector
        trusted in every direction.
    """

    iterations: int = 4
    high_pass_px: float = 3.0
    noise_grey: float = 2.0
    flow_precision_px: float = 0.25
    click_precision_px: float = 0.5
    smooth_px: float = 3.0
    fade_px: float = 90.0
    max_fb_px: float = 0.5
    min_zncc: float = 0.5
    flow_level: int = 0
    margin_px: float = 24.0
    aperture_iterations: int = 3


def grey(color: np.ndarray) -> np.ndarray:
    """Luminance (Rec. 601) of an (H, W, 3) colour image, float64 grey levels; an (H, W) grey
    image (a geometry-only or stereo scan's) as it is."""
    c = np.asarray(color, dtype=np.float64)
    if c.ndim == 2:
        return c
    return c[..., 0] * 0.299 + c[..., 1] * 0.587 + c[..., 2] * 0.114


def clipped_share(color: np.ndarray, face: np.ndarray) -> float:
    """Share of the face's pixels whose colour is clipped: a channel at the top of an integer
    image's range (255 in 8 bits), where an over-exposed or too brightly lit skin shows no
    texture for the refinement to follow.

    Parameters
    ----------
    color : (H, W, 3) or (H, W) array
        The take's colour or grey image.
    face : (H, W) bool
        The face's pixels (:func:`scan2morph.evaluate.face_region` of the pixels with a surface
        point and the take's landmarks: not the hair, the shoulders or a wall behind the head
        that a depth camera sees).

    Returns
    -------
    float
        In [0, 1]; 0 for a float image (no known top) or an empty face.
    """
    c = np.asarray(color)
    face = np.asarray(face, dtype=bool)
    if not np.issubdtype(c.dtype, np.integer) or not face.any():
        return 0.0
    top = c == np.iinfo(c.dtype).max
    clipped = top.any(axis=-1) if c.ndim == 3 else top
    return float(np.mean(clipped[face]))


@dataclass(frozen=True)
class Channel:
    """One pair of images the refinement correlates (the skin's texture, the surface's shape).

    Attributes
    ----------
    neutral, take : (H, W) float
        The neutral's and the take's image, pixel to pixel with their range images, NaN where
        there is none.
    high_pass_px : float
        The flow's high-pass scale, px (:func:`~scan2morph.refine.flow.measure_flow`'s
        ``sigma``).
    noise : float
        The images' noise in their own units: weaker contrast is not trusted.
    precision_px : float
        Precision of one confident flow vector, px (its weight is ``1 / precision^2``).
    gate_px : float or None
        When given, the channel's vectors count only where the other channels measured, and
        within this of their answer, px (a texture that may find false matches).
    match_gain : bool
        The take's image shows the neutral's skin at another exposure or light: its texture is
        scaled by its gain over the neutral's (:func:`~scan2morph.refine.flow.measure_flow`).
    """

    neutral: np.ndarray
    take: np.ndarray
    high_pass_px: float
    noise: float
    precision_px: float
    gate_px: float | None = None
    match_gain: bool = False


@dataclass(frozen=True)
class SurfaceChannel:
    """The still skin's measurement (:func:`~scan2morph.refine.shape.surface_flow`): each of
    the neutral's skin points found on the take's surface where the skin did not leave it.

    Attributes
    ----------
    neutral_xyz : (H, W, 3) float
        The neutral's range image, mm in the neutral frame.
    take_xyz : (H, W, 3) float
        The take's range image, mm in the neutral frame (its alignment applied).
    tolerance_mm : float
        Distance off the take's surface over which the confidence falls, mm.
    precision_px : float
        Precision of one confident vector, px.
    """

    neutral_xyz: np.ndarray
    take_xyz: np.ndarray
    tolerance_mm: float
    precision_px: float


def texture_channel(neutral_image, take_image, params: RefineParams) -> Channel:
    """The skin's texture as a :class:`Channel`, with the section ``refine``'s settings (the
    take's texture matched at its gain over the neutral's)."""
    return Channel(
        neutral_image,
        take_image,
        params.high_pass_px,
        params.noise_grey,
        params.flow_precision_px,
        match_gain=True,
    )


def shape_channels(
    neutral_xyz, take_xyz, transform, texture: list, params, sources=("neutral", "take")
) -> list:
    """The channels of the refinement by the surface's shape (:mod:`scan2morph.refine.shape`):
    the mean curvature's, the ``texture`` channels gated by it (the skin's, where it
    correlates; with ``params.texture``) and the still skin's (with ``params.surface``).

    Parameters
    ----------
    neutral_xyz, take_xyz : (H, W, 3) float
        The range images, mm, each in its own frame.
    transform : (4, 4) float
        Take frame -> neutral frame (the take's alignment), mm.
    texture : list of Channel
    params : ShapeParams
        The section ``refine.shape``'s settings.
    sources : (str, str)
        The neutral's and the take's range images, for messages.

    Returns
    -------
    list of Channel and SurfaceChannel
    """
    pairs = zip((neutral_xyz, take_xyz), sources, strict=True)
    images = [shape_image(xyz, params.sigma_mm, source) for xyz, source in pairs]
    shape = Channel(*images, params.high_pass_px, params.noise, params.precision_px)
    moved = transform_points(transform, np.asarray(take_xyz).reshape(-1, 3))
    surface = SurfaceChannel(
        neutral_xyz,
        moved.reshape(np.shape(take_xyz)),
        params.surface_tolerance_mm,
        params.surface_precision_px,
    )
    # a texture that does not correlate has no gain over the neutral's to match
    gated = [
        replace(
            c,
            gate_px=params.texture_gate_px,
            precision_px=params.texture_precision_px,
            match_gain=False,
        )
        for c in (texture if params.texture else [])
    ]
    return [shape, *gated] + ([surface] if params.surface else [])


def refine_points(
    vertices2d: np.ndarray,
    faces: np.ndarray,
    neutral_map: Callable[[np.ndarray], np.ndarray],
    take_map: Callable[[np.ndarray], np.ndarray],
    neutral_image: np.ndarray,
    take_image: np.ndarray,
    anchors: np.ndarray,
    params: RefineParams,
) -> tuple[np.ndarray, dict]:
    """Move a take's fitted pixel positions onto the skin points of the neutral's vertices.

    Parameters
    ----------
    vertices2d : (V, 2) float
        Template vertices, template units.
    faces : (F, 3) int
        Template triangles.
    neutral_map, take_map : callable
        The fits' maps from template coordinates (n, 2) to pixel positions (n, 2) in the
        neutral's and the take's image (their thin-plate splines: defined beyond the template).
    neutral_image, take_image : (H, W) float
        Grey images, pixel to pixel with the range images.
    anchors : (n,) int
        Template vertices the fit pinned to clicked landmarks (soft constraints).
    params : RefineParams

    Returns
    -------
    points : (V, 2) float64
        Refined pixel positions in the take's image, px (the fit's where no correction exists).
    report : dict
        ``correction`` (V, 2) the change in the take's pixel positions, px; ``confidence`` (V,)
        the measurement confidence at each vertex in [0, 1]; ``confident_share`` and
        ``median_correction_px`` (over the vertices).
    """
    channel = texture_channel(neutral_image, take_image, params)
    return refine_channels(vertices2d, faces, (neutral_map, take_map), [channel], anchors, params)


def refine_channels(
    vertices2d: np.ndarray,
    faces: np.ndarray,
    maps: tuple[Callable, Callable],
    channels: list[Channel],
    anchors: np.ndarray,
    params: RefineParams,
    give_up_share: float | None = None,
) -> tuple[np.ndarray, dict]:
    """:func:`refine_points` on several image pairs at once: each round measures the flow of
    every channel and fuses them all, each vector weighted by its confidence over its
    channel's precision squared.

    Parameters
    ----------
    vertices2d, faces, anchors, params
        As :func:`refine_points`'s.
    maps : (callable, callable)
        The neutral's and the take's fit maps (:func:`refine_points`' ``neutral_map``,
        ``take_map``).
    channels : list of Channel or SurfaceChannel
        At least one :class:`Channel`.
    give_up_share : float, optional
        After a round (but the last) whose measurement found fewer than this share of the
        vertices (those measured with confidence above one half), stop: the fit's points are
        returned, with that share and ``given_up_after_round`` in the report. The images then
        share no texture; every round measures about the same share (a stereo neutral's
        speckle against range takes: 0.07-0.11 in every round, where a textured or flat skin
        finds 0.37-1.0 from the first).

    Returns
    -------
    points, report
        As :func:`refine_points`'s; ``confidence`` is the fused weight over the weight of one
        fully confident vector of precision ``params.flow_precision_px``, clipped to [0, 1]
        (with the texture alone: its confidence).
    """
    neutral_map, take_map = maps
    v2 = np.asarray(vertices2d, dtype=np.float64)
    faces = np.asarray(faces)
    pt = _warped(take_map, v2)
    neutral_images = [
        c.neutral_xyz if isinstance(c, SurfaceChannel) else c.neutral for c in channels
    ]
    grid, references, inside = _neutral_side(
        v2, faces, neutral_map, neutral_images, channels, params
    )
    where = grid.points().reshape(-1, 2)
    mapped = _warped(take_map, where).reshape((*grid.shape, 2))
    g_vertices = grid.to_grid(v2)
    anchor_rc = np.rint(g_vertices[np.asarray(anchors, dtype=np.int64)][:, ::-1]).astype(np.int64)
    w_data = 1.0 / params.flow_precision_px**2
    smooth = w_data * params.smooth_px**2
    prior = smooth / params.fade_px**2
    anchor_w = 1.0 / (2.0 * params.click_precision_px**2)
    conf = measured = np.zeros(grid.shape)
    channels = [_sampled_take(c) for c in channels]
    apertures = _apertures(channels, references, params)
    for round_ in range(int(params.iterations)):
        flow, weight, conf, measured, (across, share) = _measure(
            channels, references, mapped, inside, params, apertures
        )
        if give_up_share is not None and round_ < int(params.iterations) - 1:
            found = _measured_share(measured, g_vertices)
            if found < give_up_share:  # the images do not correlate: no round will change it
                return pt, {
                    "correction": np.zeros_like(pt),
                    "confidence": np.zeros(len(pt)),
                    "confident_share": found,
                    "median_correction_px": 0.0,
                    "given_up_after_round": round_ + 1,
                }
        solve = fusion(weight, inside, smooth, prior, anchor_rc, anchor_w, coarsen=2)
        f = fuse_across(solve(flow), across, share, solve, params.aperture_iterations)
        mapped = compose_field(mapped, f)
    at = pull_back_field(mapped, g_vertices)
    points = np.where(np.isfinite(at).all(axis=1)[:, None], at, pt)
    vconf = np.nan_to_num(pull_back_field(conf[..., None], g_vertices)[:, 0])
    corr = points - pt
    return points, {
        "correction": corr,
        "confidence": vconf,
        "confident_share": _measured_share(measured, g_vertices),
        "median_correction_px": float(np.median(np.linalg.norm(corr, axis=1))),
    }


def _measured_share(measured: np.ndarray, g_vertices: np.ndarray) -> float:
    """Share of the vertices (their grid positions (V, 2)) whose measurement (rows, cols) is
    above one half."""
    at = np.nan_to_num(pull_back_field(measured[..., None], g_vertices)[:, 0])
    return float(np.mean(at > 0.5))


def _sampled_take(channel):
    """``channel`` with its take's image as float32, what :func:`pull_back` samples (so that
    the rounds do not convert it again each; the same samples)."""
    if isinstance(channel, SurfaceChannel):
        return replace(channel, take_xyz=np.asarray(channel.take_xyz, dtype=np.float32))
    return replace(channel, take=np.asarray(channel.take, dtype=np.float32))


def _warped(fit_map: Callable, points: np.ndarray) -> np.ndarray:
    """``fit_map(points)`` as float64, computed once per spline and points in a
    :func:`~scan2morph.refine.memo.sharing` scope (a fit's thin-plate spline)."""
    if not isinstance(fit_map, TPS):
        return np.asarray(fit_map(points), dtype=np.float64)
    parts = (fit_map.centres, fit_map.weights, fit_map.affine, points)
    return shared("tps", parts, lambda: np.asarray(fit_map(points), dtype=np.float64))


def _neutral_side(v2, faces, neutral_map, neutral_images, channels, params: RefineParams):
    """What :func:`refine_channels` measures against, from the neutral alone (the same for
    every take refined against one fit of the neutral): ``(grid, references, inside)``, the
    template grid at the neutral's pixel spacing, each channel's neutral image pulled back onto
    it and the grid points inside the domain where every image channel has a value."""

    def compute():
        grid = neutral_grid(v2, faces, neutral_map, params.margin_px)
        where = grid.points().reshape(-1, 2)
        at_neutral = _warped(neutral_map, where).reshape((*grid.shape, 2))
        references = [pull_back(image, at_neutral) for image in neutral_images]
        images = [r for r, c in zip(references, channels, strict=True) if isinstance(c, Channel)]
        inside = grid.domain & np.all([np.isfinite(r) for r in images], axis=0)
        return grid, references, inside

    if not (active() and isinstance(neutral_map, TPS)):
        return compute()
    kinds = tuple(isinstance(c, Channel) for c in channels)
    parts = (neutral_map.centres, neutral_map.weights, neutral_map.affine, v2, faces)
    return shared("neutral", (*parts, params.margin_px, kinds, *neutral_images), compute)


def neutral_grid(vertices2d, faces, neutral_map: Callable, margin_px: float) -> TemplateGrid:
    """The template grid a refinement compares on: the template (vertices (V, 2), triangles
    (F, 3)) sampled at the neutral's pixel spacing (the median ratio of the template's edge
    lengths to the neutral fit's, ``neutral_map`` its map to the neutral's pixels), with
    ``margin_px`` grid points around the outline."""
    v2 = np.asarray(vertices2d, dtype=np.float64)
    pn = _warped(neutral_map, v2)
    e = face_sides(faces)
    ratio = np.linalg.norm(v2[e[:, 0]] - v2[e[:, 1]], axis=1) / np.linalg.norm(
        pn[e[:, 0]] - pn[e[:, 1]], axis=1
    )
    step = float(np.median(ratio[np.isfinite(ratio)]))  # template units per neutral pixel
    return template_grid(v2, faces, step, int(np.ceil(margin_px)))


def _apertures(channels, references, params: RefineParams) -> list:
    """Each channel's :func:`~scan2morph.refine.flow.aperture` (None for all when
    ``params.aperture_iterations`` is 0), each reference's computed once: an image channel's
    of its own reference; the still skin's that of the first image channel (the surface's
    shape, in the shape's refinement: a point slid along a smooth surface stays on it, so the
    still skin measures only where the shape has texture, and the same way)."""
    if not params.aperture_iterations:
        return [None] * len(channels)
    own = [
        shared("aperture", (r, c.high_pass_px, c.noise), lambda r=r, c=c: aperture(
            r, c.high_pass_px, c.noise
        )) if isinstance(c, Channel) else None
        for c, r in zip(channels, references, strict=True)
    ]  # fmt: skip
    first = next((a for a in own if a is not None), None)
    return [first if a is None else a for a in own]


def _measure(channels, references, mapped, inside, params: RefineParams, apertures):
    """Every channel's flow from its reference to its take image pulled back through
    ``mapped``, averaged by weight: ``(flow (rows, cols, 2), weight, confidence, measured,
    (across, share))`` (the middle three (rows, cols)), the weight the sum of each channel's
    confidence over its precision squared, the confidence that weight over ``1 /
    params.flow_precision_px^2`` and ``measured`` the sum of the channels' confidences, both at
    most 1 (one image channel: its own confidence and measurement as they are when its
    precision is ``params.flow_precision_px``, the texture's refinement). ``across`` (rows,
    cols, 2) is the weighted mean of each channel's vector projected by its ``apertures``
    projector and ``share`` (rows, cols, 2, 2) the weighted mean of those projectors (both None
    when no channel has one: every direction trusted). A channel with a ``gate_px`` counts after the others, only
    where they measured and its vector lies within ``gate_px`` of theirs."""
    lone = len(channels) == 1 and isinstance(channels[0], Channel)
    if lone and channels[0].precision_px == params.flow_precision_px:
        flow, conf = _channel_flow(channels[0], references[0], mapped, inside, params)
        share = apertures[0]
        across = None if share is None else np.einsum("rcij,rcj->rci", share, flow)
        return flow, conf * (1.0 / channels[0].precision_px ** 2), conf, conf, (across, share)
    total = np.zeros(inside.shape)
    summed = np.zeros(inside.shape)
    acc = np.zeros((*inside.shape, 2))
    acc_across = np.zeros((*inside.shape, 2))
    acc_share = np.zeros((*inside.shape, 2, 2))
    order = sorted(range(len(channels)), key=lambda k: _gate(channels[k]) < np.inf)
    for k in order:
        channel = channels[k]
        flow, conf = _channel_flow(channel, references[k], mapped, inside, params)
        if _gate(channel) < np.inf:
            with np.errstate(invalid="ignore", divide="ignore"):
                others = acc / total[..., None]
            near = lengths_2d(flow - others) <= _gate(channel)
            conf = np.where((total > 0) & near, conf, 0.0)
        w = conf / channel.precision_px**2
        summed += conf
        total += w
        acc += w[..., None] * flow
        if apertures[k] is not None:
            acc_across += w[..., None] * np.einsum("rcij,rcj->rci", apertures[k], flow)
            acc_share += w[..., None, None] * apertures[k]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(total[..., None] > 0, acc / total[..., None], 0.0)
        across = np.where(total[..., None] > 0, acc_across / total[..., None], 0.0)
        share = np.where(total[..., None, None] > 0, acc_share / total[..., None, None], np.eye(2))
    confidence = np.clip(total * params.flow_precision_px**2, 0.0, 1.0)
    if all(a is None for a in apertures):  # every direction trusted: nothing to project
        across = share = None
    return mean, total, confidence, np.clip(summed, 0.0, 1.0), (across, share)


def _gate(channel) -> float:
    """A channel's ``gate_px`` (inf: none)."""
    gate = getattr(channel, "gate_px", None)
    return np.inf if gate is None else float(gate)


def _channel_flow(channel, reference, mapped, inside, params: RefineParams):
    """One channel's ``(flow, confidence)`` on the grid (see :func:`_measure`)."""
    if isinstance(channel, SurfaceChannel):
        flow, conf = surface_flow(reference, channel.take_xyz, mapped, channel.tolerance_mm)
        return flow, np.where(inside, conf, 0.0)
    moving = pull_back(channel.take, mapped)
    return measure_flow(
        reference,
        np.where(inside, moving, np.nan),
        sigma=channel.high_pass_px,
        noise=channel.noise,
        max_fb_px=params.max_fb_px,
        min_zncc=params.min_zncc,
        level=params.flow_level,
        match_gain=channel.match_gain,
    )


def compose_field(field: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """``field(x + flow(x))`` on the grid (bilinear; NaN stays NaN)."""
    rows, cols = flow.shape[:2]
    gx, gy = np.meshgrid(np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64))
    pts = np.stack([gx + flow[..., 0], gy + flow[..., 1]], axis=-1)
    return pull_back_field(field, pts)


def pull_back_field(field: np.ndarray, grid_points: np.ndarray) -> np.ndarray:
    """A (rows, cols, k) field sampled bilinearly at grid positions (..., 2) (x=column, y=row),
    float64; NaN where any of the four neighbours is NaN or outside the grid."""
    rows, cols, k = field.shape
    p = np.asarray(grid_points, dtype=np.float64)
    x, y = p[..., 0], p[..., 1]
    ok = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (y >= 0) & (x <= cols - 1) & (y <= rows - 1)
    xs, ys = np.where(ok, x, 0), np.where(ok, y, 0)
    x0 = np.clip(np.floor(xs).astype(np.int64), 0, max(cols - 2, 0))
    y0 = np.clip(np.floor(ys).astype(np.int64), 0, max(rows - 2, 0))
    fx, fy = xs - x0, ys - y0
    gx, gy = 1 - fx, 1 - fy
    # the four neighbours gathered by flat index (np.take: 40% faster than 2-D fancy indexing)
    flat, i = field.reshape(-1, k), y0 * cols + x0
    out = (
        np.take(flat, i, axis=0) * (gx * gy)[..., None]
        + np.take(flat, i + 1, axis=0) * (fx * gy)[..., None]
        + np.take(flat, i + cols, axis=0) * (gx * fy)[..., None]
        + np.take(flat, i + cols + 1, axis=0) * (fx * fy)[..., None]
    )
    out[~ok] = np.nan
    return out
