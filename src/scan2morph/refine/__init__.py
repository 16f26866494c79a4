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
from dataclasses import dataclass

import numpy as np

from scan2morph.refine.flow import fuse, measure_flow
from scan2morph.refine.template_space import pull_back, template_grid

__all__ = ["RefineParams", "refine_points", "grey"]


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


def grey(color: np.ndarray) -> np.ndarray:
    """Luminance (Rec. 601) of an (H, W, 3) colour image, float64 grey levels; an (H, W) grey
    image (a geometry-only or stereo scan's) as it is."""
    c = np.asarray(color, dtype=np.float64)
    if c.ndim == 2:
        return c
    return c[..., 0] * 0.299 + c[..., 1] * 0.587 + c[..., 2] * 0.114


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
    v2 = np.asarray(vertices2d, dtype=np.float64)
    pn = np.asarray(neutral_map(v2), dtype=np.float64)
    pt = np.asarray(take_map(v2), dtype=np.float64)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    ratio = np.linalg.norm(v2[e[:, 0]] - v2[e[:, 1]], axis=1) / np.linalg.norm(
        pn[e[:, 0]] - pn[e[:, 1]], axis=1
    )
    step = float(np.median(ratio[np.isfinite(ratio)]))  # template units per neutral pixel
    grid = template_grid(v2, faces, step, int(np.ceil(params.margin_px)))
    where = grid.points().reshape(-1, 2)
    shape = (*grid.shape, 2)
    reference = pull_back(neutral_image, np.asarray(neutral_map(where)).reshape(shape))
    mapped = np.asarray(take_map(where), dtype=np.float64).reshape(shape)
    inside = grid.domain & np.isfinite(reference)
    g_vertices = grid.to_grid(v2)
    anchor_rc = np.rint(g_vertices[np.asarray(anchors, dtype=np.int64)][:, ::-1]).astype(np.int64)
    w_data = 1.0 / params.flow_precision_px**2
    smooth = w_data * params.smooth_px**2
    prior = smooth / params.fade_px**2
    anchor_w = 1.0 / (2.0 * params.click_precision_px**2)
    conf = np.zeros(grid.shape)
    for _ in range(int(params.iterations)):
        moving = pull_back(take_image, mapped)
        flow, conf = measure_flow(
            reference,
            np.where(inside, moving, np.nan),
            sigma=params.high_pass_px,
            noise=params.noise_grey,
            max_fb_px=params.max_fb_px,
            min_zncc=params.min_zncc,
            level=params.flow_level,
        )
        f = fuse(flow, w_data * conf, inside, smooth, prior, anchor_rc, anchor_w, coarsen=2)
        mapped = _compose(mapped, f)
    at = pull_back_field(mapped, g_vertices)
    points = np.where(np.isfinite(at).all(axis=1)[:, None], at, pt)
    vconf = pull_back_field(conf[..., None], g_vertices)[:, 0]
    corr = points - pt
    return points, {
        "correction": corr,
        "confidence": np.nan_to_num(vconf),
        "confident_share": float(np.mean(np.nan_to_num(vconf) > 0.5)),
        "median_correction_px": float(np.median(np.linalg.norm(corr, axis=1))),
    }


def _compose(field: np.ndarray, flow: np.ndarray) -> np.ndarray:
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
    x0 = np.clip(np.floor(np.where(ok, x, 0)).astype(np.int64), 0, max(cols - 2, 0))
    y0 = np.clip(np.floor(np.where(ok, y, 0)).astype(np.int64), 0, max(rows - 2, 0))
    fx, fy = np.where(ok, x, 0) - x0, np.where(ok, y, 0) - y0
    out = (
        field[y0, x0] * ((1 - fx) * (1 - fy))[..., None]
        + field[y0, x0 + 1] * (fx * (1 - fy))[..., None]
        + field[y0 + 1, x0] * ((1 - fx) * fy)[..., None]
        + field[y0 + 1, x0 + 1] * (fx * fy)[..., None]
    )
    out[~ok] = np.nan
    return out
