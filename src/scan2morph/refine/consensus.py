"""The takes' consensus: a subject's takes registered to one another by their shared texture.

A take refined against its neutral by image correlation lands its vertices on the neutral's skin
points. Where the neutral's texture does not match the takes' (a stereo neutral with a speckle
pattern, the expressions from a laser scanner) the takes are refined by the surface's shape
(:mod:`scan2morph.refine.shape`), which leaves each take's vertices off their skin points by an
error of about a millimetre, mostly along the surface, different in every take. The takes still
share one texture among themselves. Pulled back into template space through their refined maps,
take ``i``'s image shows the skin at ``x + e_i(x)``, ``e_i`` its map's error; the mean of all the
takes' pulled-back images shows it at about ``x + e(x)``, ``e`` the mean error. The flow from
that mean image to take ``i``'s (:func:`~scan2morph.refine.flow.measure_flow`, fused as the
refinement fuses it) measures ``e - e_i``; moving each take's map by it, less the takes' mean
flow (the mean error cannot be seen), leaves every take with the mean error ``e`` instead of its
own: errors that differ from take to take average out.

:func:`take_consensus` does this on the template grid (:mod:`scan2morph.refine.template_space`),
a few rounds, each on the images pulled back through the last maps.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scan2morph.refine import RefineParams, compose_field, pull_back_field
from scan2morph.refine.flow import fusion, measure_flow
from scan2morph.refine.template_space import TemplateGrid, pull_back

#: Takes a grid point's mean image needs (fewer: no mean there).
MIN_TAKES = 3


def take_consensus(
    grid: TemplateGrid,
    vertices2d: np.ndarray,
    points: Mapping[str, np.ndarray],
    images: Mapping[str, np.ndarray],
    params: RefineParams,
    rounds: int = 2,
) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """Move each take's refined pixel positions onto the skin points all the takes agree on.

    Parameters
    ----------
    grid : TemplateGrid
        The template grid the takes are compared on (the refinement's: the neutral's pixel
        spacing).
    vertices2d : (V, 2) float
        The template's vertices, template units.
    points : mapping take -> (V, 2) float
        Each take's refined pixel positions of the template's vertices in its own image, px
        (NaN where it has none); at least :data:`MIN_TAKES` takes.
    images : mapping take -> (H, W) float
        Each take's grey image, pixel to pixel with its range image (NaN where there is none).
    params : RefineParams
        The flow's settings (``high_pass_px``, ``noise_grey``, ``max_fb_px``, ``min_zncc``,
        ``flow_level``) and the fusion's (``flow_precision_px``, ``smooth_px``, ``fade_px``).
    rounds : int
        Measure-and-move rounds.

    Returns
    -------
    points : dict take -> (V, 2) float64
        The moved pixel positions, px (a take's own where its map has no value).
    report : dict take -> dict
        ``confident_share``: the share of the template grid's points where the last round
        measured the take with confidence above one half; ``median_correction_px``: the median
        move of its vertices, px.

    Raises
    ------
    ValueError
        Fewer than :data:`MIN_TAKES` takes, or ``rounds`` < 1.
    """
    takes = list(points)
    if len(takes) < MIN_TAKES:
        raise ValueError(f"a consensus needs at least {MIN_TAKES} takes, got {len(takes)}")
    if int(rounds) < 1:
        raise ValueError(f"rounds: expected at least 1, got {rounds!r}")
    at_vertices = grid.to_grid(np.asarray(vertices2d, dtype=np.float64))
    maps = {t: grid.interpolate(np.asarray(points[t], dtype=np.float64)) for t in takes}
    grey = {t: np.asarray(images[t], dtype=np.float32) for t in takes}
    w_data = 1.0 / params.flow_precision_px**2
    smooth = w_data * params.smooth_px**2
    prior = smooth / params.fade_px**2
    confidence = {}
    for _ in range(int(rounds)):
        pulled = np.stack([pull_back(grey[t], maps[t]) for t in takes])
        seen = np.isfinite(pulled)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(seen, pulled, 0.0).sum(axis=0) / seen.sum(axis=0)
        mean[seen.sum(axis=0) < MIN_TAKES] = np.nan
        region = grid.domain & np.isfinite(mean)
        fields = []
        for k, take in enumerate(takes):
            flow, conf = measure_flow(
                mean,
                np.where(region & seen[k], pulled[k], np.nan),
                sigma=params.high_pass_px,
                noise=params.noise_grey,
                max_fb_px=params.max_fb_px,
                min_zncc=params.min_zncc,
                level=params.flow_level,
            )
            confidence[take] = conf
            fields.append(fusion(conf * w_data, region, smooth, prior, coarsen=2)(flow))
        fields = np.stack(fields)
        known = np.isfinite(fields).all(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            drift = (
                np.where(known[..., None], fields, 0.0).sum(axis=0) / known.sum(axis=0)[..., None]
            )
        for k, take in enumerate(takes):
            move = np.where(known[k][..., None], fields[k] - drift, 0.0)
            maps[take] = compose_field(maps[take], move)
    out, report = {}, {}
    for take in takes:
        old = np.asarray(points[take], dtype=np.float64)
        new = pull_back_field(maps[take], at_vertices)
        new = np.where(np.isfinite(new).all(axis=1)[:, None], new, old)
        out[take] = new
        moved = np.linalg.norm(new - old, axis=1)
        report[take] = {
            "confident_share": float(np.mean(confidence[take][grid.domain] > 0.5)),
            "median_correction_px": float(np.nanmedian(moved)) if np.isfinite(moved).any() else 0.0,
        }
    return out, report


__all__ = ["MIN_TAKES", "take_consensus"]
