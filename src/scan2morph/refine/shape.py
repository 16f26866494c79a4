"""The surface's shape as an image: what the refinement correlates where the skin's texture does
not match the neutral's (another camera, a projected pattern, a geometry-only scan).

The shape image of a range image is the surface's mean curvature at a scale given in
millimetres, on the range image's own pixel grid: the creases, the lips' edges, the nasolabial
folds, the eyelids and the nose's wings are its features. Curvature does not change under a
rigid motion of the face or of the camera, so the neutral's and a take's shape images agree
where the skin kept its shape, whatever their sensors, and image correlation
(:func:`~scan2morph.refine.flow.measure_flow`) measures how the skin slid between them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

from scan2morph.errors import InputError, require_numbers
from scan2morph.geometry import finite_points
from scan2morph.refine.memo import shared
from scan2morph.refine.template_space import pull_back

#: Shape images are in 1/m (curvature in 1/mm times this): the flow's grey-level settings
#: (``noise``) then read as curvature in 1/m.
PER_METRE = 1000.0
#: Least share of a Gaussian window's weight on data for a smoothed pixel to count.
MIN_COVER = 0.5


@dataclass(frozen=True)
class ShapeParams:
    """The shape-driven refinement (config section ``refine.shape``).

    Attributes
    ----------
    use : bool
        Refine by the shape image (with whatever texture correlates) a take whose texture
        does not correlate with the neutral's (a geometry-only scan keeps its template fit).
    sigma_mm : float
        Scale of the curvature, mm (Gaussian smoothing of the surface before differentiating).
    high_pass_px : float
        The flow's high-pass scale on the shape image, px of the neutral's image.
    noise : float
        Curvature noise, 1/m: weaker shape is not trusted.
    precision_px : float
        Precision of one confident shape flow vector, px (its weight is ``1 / precision^2``).
    min_confident_share : float
        Least share of the face confidently measured (by the shape, the still skin and the
        texture together) for the shape-driven refinement to be used; below it the take keeps
        its template fit.
    fade_px : float
        Where nothing is measured, the correction fades back to the fit over about this, px
        (the section ``refine``'s ``fade_px`` for this refinement: the mouth's skin, which
        leaves the surface and changes its shape, is measured by neither).
    texture : bool
        Add the skin's texture (its flow where it correlates: a stereo neutral's speckle lies
        over the skin's own texture). A texture wholly unrelated to the neutral's finds false
        matches, which its weight (``refine.flow_precision_px``) would let outweigh the shape:
        its vectors count only within ``texture_gate_px`` of the shape's and the still skin's
        answer, where those measured.
    texture_gate_px : float
        That gate, px (``.inf``: the texture's vectors count wherever they are confident).
    texture_precision_px : float
        Precision of one confident texture vector here, px.
    surface : bool
        Add the still skin's measurement (:func:`surface_flow`) to the shape's.
    surface_tolerance_mm : float
        The still skin's measurement (:func:`surface_flow`): distance of the neutral's point
        off the take's surface over which its confidence falls, mm.
    surface_precision_px : float
        Precision of one confident still-skin vector, px.
    """

    use: bool = True
    sigma_mm: float = 2.0
    high_pass_px: float = 8.0
    noise: float = 10.0
    precision_px: float = 1.0
    min_confident_share: float = 0.1
    fade_px: float = 30.0
    texture: bool = True
    texture_gate_px: float = 1.0
    texture_precision_px: float = 0.25
    surface: bool = True
    surface_tolerance_mm: float = 0.2
    surface_precision_px: float = 1.0

    def __post_init__(self):
        for name in ("use", "texture", "surface"):
            if not isinstance(getattr(self, name), bool | np.bool_):
                raise InputError(
                    "ShapeParams", f"{name}: expected true or false, got {getattr(self, name)!r}"
                )
        names = (
            "sigma_mm",
            "high_pass_px",
            "noise",
            "precision_px",
            "fade_px",
            "texture_gate_px",
            "texture_precision_px",
            "surface_tolerance_mm",
            "surface_precision_px",
            "min_confident_share",
        )
        require_numbers("ShapeParams", {n: getattr(self, n) for n in names})
        for name in names[:-1]:
            if not getattr(self, name) > 0:  # NaN too
                raise InputError(
                    "ShapeParams", f"{name}: expected a number > 0, got {getattr(self, name)!r}"
                )
        if not 0 <= self.min_confident_share <= 1:
            raise InputError(
                "ShapeParams",
                f"min_confident_share: expected a share 0..1, got {self.min_confident_share!r}",
            )


def pixel_spacing(xyz: np.ndarray) -> float:
    """Median distance between neighbouring pixels' points of a range image, mm per px.

    Parameters
    ----------
    xyz : (H, W, 3) float
        mm, NaN where there is no data.

    Returns
    -------
    float
        NaN when no two neighbouring pixels have data.
    """
    d = np.concatenate(
        [
            np.linalg.norm(np.diff(xyz, axis=1), axis=-1).ravel(),
            np.linalg.norm(np.diff(xyz, axis=0), axis=-1).ravel(),
        ]
    )
    d = d[np.isfinite(d)]
    return float(np.median(d)) if len(d) else float("nan")


def shape_image(xyz: np.ndarray, sigma_mm: float, source: str = "range image") -> np.ndarray:
    """Mean curvature of a range image's surface at a scale, on its pixel grid.

    Parameters
    ----------
    xyz : (H, W, 3) float
        The surface, mm, NaN where there is no data.
    sigma_mm : float
        Gaussian scale of the smoothing before differentiating, mm (converted to pixels by the
        image's own :func:`pixel_spacing`).
    source : str
        Named in the error.

    Returns
    -------
    (H, W) float64
        Mean curvature in 1/m (:data:`PER_METRE`), positive where the surface bulges towards
        the camera (the nose's tip, the lips); NaN where there is no data.

    Raises
    ------
    InputError
        When ``xyz`` is not (H, W, 3) or has fewer than two neighbouring pixels with data.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[-1] != 3:
        raise InputError(source, f"xyz: expected an (H, W, 3) range image, got {xyz.shape}")
    # a take's shape image is the same in every click-noise draw (computed once in a scope)
    return shared("shape_image", (xyz, float(sigma_mm)), lambda: _curvature(xyz, sigma_mm, source))


def _curvature(xyz: np.ndarray, sigma_mm: float, source: str) -> np.ndarray:
    """:func:`shape_image` of a checked (H, W, 3) float64 range image."""
    spacing = pixel_spacing(xyz)
    if not np.isfinite(spacing) or spacing <= 0:
        raise InputError(source, "xyz: no two neighbouring pixels with data to measure a shape")
    s = float(sigma_mm) / spacing
    mask = finite_points(xyz)
    cover = gaussian_filter(mask.astype(np.float64), s)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.stack(
            [gaussian_filter(np.where(mask, xyz[..., k], 0.0), s) / cover for k in range(3)],
            axis=-1,
        )
    xu, xv = np.gradient(x, axis=1), np.gradient(x, axis=0)
    xuu, xuv = np.gradient(xu, axis=1), np.gradient(xu, axis=0)
    xvv = np.gradient(xv, axis=0)
    # towards the camera in any frame: a grid of x right and y down (ingest checks each take's
    # handedness) has xu x xv pointing away from the viewer, wherever the frame's origin lies
    n = -np.cross(xu, xv)
    with np.errstate(invalid="ignore", divide="ignore"):  # a degenerate pixel: NaN, not ok
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
    ok = mask & (cover >= MIN_COVER) & finite_points(n)
    if not ok.any():
        return np.full(mask.shape, np.nan)
    big_e, big_f, big_g = _dot(xu, xu), _dot(xu, xv), _dot(xv, xv)
    e, f, g = _dot(xuu, n), _dot(xuv, n), _dot(xvv, n)
    with np.errstate(invalid="ignore", divide="ignore"):
        h = (e * big_g - 2 * f * big_f + g * big_e) / (2 * (big_e * big_g - big_f**2))
    # the normal points to the camera: a bump towards it curves away from the normal (h < 0)
    return np.where(ok & np.isfinite(h), -h * PER_METRE, np.nan)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The dot products of two (..., 3) arrays along their last axis, (...)."""
    return np.einsum("...k,...k->...", a, b)


def surface_flow(
    reference: np.ndarray, take_xyz: np.ndarray, mapped: np.ndarray, tolerance_mm: float
) -> tuple[np.ndarray, np.ndarray]:
    """Where on the take's surface each of the neutral's skin points lies, as a flow on the
    template grid: the still skin's answer (after the alignment a point that did not move is
    where it was).

    The take's surface point at each grid point (its range image sampled at ``mapped``) is
    moved along the surface, by a Gauss-Newton step in grid coordinates, to the foot of the
    neutral's point on the surface's tangent plane. A point the skin carried off the surface
    (the neutral's point more than ``tolerance_mm`` from the take's tangent plane) moved, and
    tells nothing of where: its confidence falls as ``exp(-(d / tolerance_mm)^2 / 2)``.

    Parameters
    ----------
    reference : (rows, columns, 3) float
        The neutral's skin point at each grid point, mm in the neutral frame (NaN: none).
    take_xyz : (H, W, 3) float
        The take's range image in the neutral frame (the alignment applied), mm.
    mapped : (rows, columns, 2) float
        Each grid point's pixel position in the take's image.
    tolerance_mm : float

    Returns
    -------
    flow : (rows, columns, 2) float64
        Grid px, ``take(mapped(x + flow(x))) ~ reference(x)``; 0 where unknown.
    confidence : (rows, columns) float64
        In [0, 1].
    """
    xt = pull_back(take_xyz, mapped).astype(np.float64)
    ju, jv = np.gradient(xt, axis=1), np.gradient(xt, axis=0)
    n = np.cross(ju, jv)
    with np.errstate(invalid="ignore", divide="ignore"):  # a degenerate grid point: NaN
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
    d = np.asarray(reference, dtype=np.float64) - xt
    dn = _dot(d, n)
    tangential = d - dn[..., None] * n
    # J delta = tangential, J = [ju jv] (3 x 2): the normal equations' 2 x 2 solve per point
    a, b, c = _dot(ju, ju), _dot(ju, jv), _dot(jv, jv)
    ru, rv = _dot(ju, tangential), _dot(jv, tangential)
    with np.errstate(invalid="ignore", divide="ignore"):
        det = a * c - b * b
        flow = np.stack([(c * ru - b * rv) / det, (a * rv - b * ru) / det], axis=-1)
        conf = np.exp(-0.5 * (dn / tolerance_mm) ** 2)
    ok = finite_points(flow) & np.isfinite(conf) & (det > 0)
    return np.where(ok[..., None], flow, 0.0), np.where(ok, conf, 0.0)
