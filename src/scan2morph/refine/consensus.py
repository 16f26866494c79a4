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
from scipy.ndimage import distance_transform_edt

from scan2morph.geometry import affine_fit
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
    min_share: float = 0.0,
) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """Move each take's refined pixel positions onto the skin points all the takes agree on.

    Parameters
    ----------
    grid : TemplateGrid
        The template grid the takes are compared on (the refinement's: the neutral's pixel
        spacing, with a margin around the template's outline).
    vertices2d : (V, 2) float
        The template's vertices, template units.
    points : mapping take -> (V, 2) float
        Each take's refined pixel positions of the template's vertices in its own image, px;
        at least :data:`MIN_TAKES` takes.
    images : mapping take -> (H, W) float
        Each take's grey image, pixel to pixel with its range image (NaN where there is none).
    params : RefineParams
        The flow's settings (``high_pass_px``, ``noise_grey``, ``max_fb_px``, ``min_zncc``,
        ``flow_level``) and the fusion's (``flow_precision_px``, ``smooth_px``, ``fade_px``).
    rounds : int
        Measure-and-move rounds.
    min_share : float
        A take measured against the others' mean image with confidence above one half on less
        than this share of the template (its texture is not theirs) is left out, and the
        consensus made again without it.

    Returns
    -------
    points : dict take -> (V, 2) float64
        The moved pixel positions of the takes kept, px.
    report : dict take -> dict
        Every take's ``confident_share`` (the share of the template's grid points the last
        round it took part in measured it with confidence above one half) and ``kept``; a kept
        take's ``median_correction_px``, the median move of its vertices, px.

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
    v2 = np.asarray(vertices2d, dtype=np.float64)
    maps = {t: extended_map(grid, v2, np.asarray(points[t], dtype=np.float64)) for t in takes}
    grey = {t: np.asarray(images[t], dtype=np.float32) for t in takes}
    report: dict[str, dict] = {}
    while True:
        moved, shares = _rounds(grid, {t: maps[t] for t in takes}, grey, params, int(rounds))
        low = [t for t in takes if shares[t] < min_share]
        report |= {t: {"confident_share": shares[t], "kept": t not in low} for t in takes}
        if not low or len(takes) - len(low) < MIN_TAKES:
            break
        takes = [t for t in takes if t not in low]  # made again without them
    if low:  # too few kept: nothing moves
        return {}, {t: r | {"kept": False} for t, r in report.items()}
    at_vertices = grid.to_grid(v2)
    out = {}
    for take in takes:
        old = np.asarray(points[take], dtype=np.float64)
        new = pull_back_field(moved[take], at_vertices)
        out[take] = np.where(np.isfinite(new).all(axis=1)[:, None], new, old)
        report[take]["median_correction_px"] = float(
            np.nanmedian(np.linalg.norm(out[take] - old, axis=1))
        )
    return out, report


def extended_map(grid: TemplateGrid, vertices2d: np.ndarray, points: np.ndarray) -> np.ndarray:
    """A take's map from the grid to its pixels, (rows, columns, 2) px: piecewise linear over the
    template through its vertices' pixel positions ``points`` (V, 2), and beyond (the grid's
    margin, a triangle with a vertex without a position) the affine map that fits the vertices
    best plus the nearest residual from it, so that an outline vertex can move outwards."""
    ok = np.isfinite(points).all(axis=1)
    affine = affine_fit(vertices2d[ok], points[ok])
    plane = np.column_stack([vertices2d, np.ones(len(vertices2d))]) @ affine
    residual = grid.interpolate(points - plane)
    known = np.isfinite(residual).all(axis=-1)
    if known.any() and not known.all():
        rows, cols = distance_transform_edt(~known, return_distances=False, return_indices=True)
        residual = residual[rows, cols]
    where = grid.points()
    return where @ affine[:2] + affine[2] + np.nan_to_num(residual)


def _rounds(grid: TemplateGrid, maps: dict, grey: dict, params: RefineParams, rounds: int):
    """:func:`take_consensus`'s rounds on the takes of ``maps``: their moved maps and each one's
    share of the template's grid points measured with confidence above one half."""
    takes = list(maps)
    w_data = 1.0 / params.flow_precision_px**2
    smooth = w_data * params.smooth_px**2
    prior = smooth / params.fade_px**2
    shares = {}
    for _ in range(rounds):
        pulled = np.stack([pull_back(grey[t], maps[t]) for t in takes])
        seen = np.isfinite(pulled) & grid.domain
        count = seen.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(seen, pulled, 0.0).sum(axis=0) / count
        mean[count < MIN_TAKES] = np.nan
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
            shares[take] = float(np.mean(conf[grid.inside] > 0.5))
            fields.append(fusion(conf * w_data, region, smooth, prior, coarsen=2)(flow))
        fields = np.stack(fields)
        # the takes' mean move where each is seen (the mean error cannot be seen)
        weight = (seen & region).astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            drift = np.einsum("krc,krcd->rcd", weight, fields) / weight.sum(axis=0)[..., None]
        drift = np.nan_to_num(drift)
        for k, take in enumerate(takes):
            maps[take] = compose_field(maps[take], fields[k] - drift)
    return maps, shares


__all__ = ["MIN_TAKES", "extended_map", "take_consensus"]
