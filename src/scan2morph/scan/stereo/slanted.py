"""Per-pixel matching with a small slanted window: refinement, growth and validation.

:class:`_PatchMatcher` compares a left pixel's own small window with the right image along the
local shape of its disparity (ZNCC, Gauss-Newton): the plane of its disparity gradient, and by
default the curvature too (:func:`_disparity_shape`). It refines every matched pixel
(:func:`_refine_patches`), grows the matches into unmatched neighbours (:func:`_grow`) and
validates every pixel by its own evidence (:func:`_validate`).

Why the curvature: a window that assumes a plane matches the disparity averaged over the window,
so a ridge or a tip comes out flattened by about ``sigma**2 / 2`` times the disparity's second
derivative (nose ridge of the default rig: 0.05-0.08 mm towards the cameras' far side). The
window that follows the curvature of the (smoothed) disparity field matches the pixel itself.
"""

from __future__ import annotations

import cv2
import numpy as np

#: Most rows of one :func:`cv2.remap` table (OpenCV takes fewer than 32767).
_REMAP_ROWS = 32000

#: Columns of a disparity shape (:func:`_disparity_shape`): gradient ``a = dd/dx``,
#: ``b = dd/dy`` (px per px) and second derivatives ``dd/dxx``, ``dd/dxdy``, ``dd/dyy`` (px per
#: px squared).
SHAPE_COLUMNS = ("a", "b", "xx", "xy", "yy")


def _sample(
    image: np.ndarray, map_x: np.ndarray, map_y: np.ndarray, interpolation: int = cv2.INTER_CUBIC
) -> np.ndarray:
    """Sample an image at arbitrary positions (:func:`cv2.remap` in blocks of rows).

    Parameters
    ----------
    image : (h, w) float32
    map_x, map_y : (n, k) float32
        Positions, px ((0, 0) = centre of the top-left pixel).
    interpolation : int
        OpenCV interpolation flag.

    Returns
    -------
    (n, k) float32
        The image there (replicated beyond its border).
    """
    out = np.empty(map_x.shape, np.float32)
    for start in range(0, map_x.shape[0], _REMAP_ROWS):
        rows = slice(start, start + _REMAP_ROWS)
        out[rows] = cv2.remap(
            image, map_x[rows], map_y[rows], interpolation, borderMode=cv2.BORDER_REPLICATE
        )
    return out


def _standardise(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Standardise windows in place: minus their weighted mean, over their weighted std.

    Parameters
    ----------
    values : (n, k) float32
        One window per row; overwritten.
    weights : (k,) float32
        Window weights, summing to 1.

    Returns
    -------
    (n,) float32
        1 / std of every window (before standardising).
    """
    values -= (values @ weights)[:, None]
    inv_std = 1.0 / np.sqrt(np.einsum("ij,ij,j->i", values, values, weights, optimize=True) + 1e-6)
    values *= inv_std[:, None]
    return inv_std


class _PatchMatcher:
    """Match single rectified left pixels in the right image with a small slanted window.

    The window of left pixel ``(x, y)`` holds the pixels ``(x + ox, y + oy)``,
    ``|ox|, |oy| <= radius``, Gaussian weighted (``sigma``); they match the right image at
    ``(x + ox - D(ox, oy), y + oy)`` with ``D = d + a ox + b oy + (xx ox^2 + 2 xy ox oy +
    yy oy^2) / 2``: the window follows the disparity ``d`` with its gradient ``(a, b)`` (px per
    px) and second derivatives (the pixel's *shape*, :data:`SHAPE_COLUMNS`), so slanted,
    foreshortened and curved surfaces match as well as fronto-parallel ones, and the result
    belongs to the pixel (a window of a few pixels). The windows are compared after removing
    their mean and gain (ZNCC).

    Parameters
    ----------
    left_r, right_r : (h, w) uint8
        Rectified grey images.
    radius : int
        Half side of the window, px.
    sigma : float
        Gaussian weight of the window, px.
    """

    def __init__(self, left_r: np.ndarray, right_r: np.ndarray, radius: int, sigma: float):
        h, w = left_r.shape
        left = left_r.astype(np.float32)
        self.right = right_r.astype(np.float32)
        self.right_dx = cv2.Sobel(self.right, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        o = np.arange(-radius, radius + 1)
        oy, ox = (t.ravel() for t in np.meshgrid(o, o, indexing="ij"))
        self.steps = o.astype(np.float32)
        self.ox, self.oy = ox.astype(np.float32), oy.astype(np.float32)
        # the window's quadratic monomials, (3, k): the shape's xx, xy, yy terms per pixel
        self.quadratic = np.stack([ox * ox / 2.0, ox * oy, oy * oy / 2.0]).astype(np.float32)
        # the left image and its x-gradient, flattened with a margin so that every window of
        # a canvas pixel can be gathered with flat offsets (windows cut by the left or right
        # border wrap to the neighbouring row)
        self.width, self.margin = w, radius * (w + 1)
        self.offsets = oy * w + ox + self.margin
        dx = cv2.Sobel(left, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        self.left_flat, self.left_dx_flat = (np.pad(a.ravel(), self.margin) for a in (left, dx))
        weights = np.exp(-(ox * ox + oy * oy) / (2.0 * sigma * sigma)).astype(np.float32)
        self.weights = weights / weights.sum()

    def left_windows(self, ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Standardised left windows of canvas pixels and their x-gradients.

        Parameters
        ----------
        ys, xs : (n,) int
            Pixels of the rectified canvas.

        Returns
        -------
        values, dx : (n, k) float32
            The standardised windows and the image x-gradient there, divided by the same std.
        """
        flat = (ys * self.width + xs)[:, None] + self.offsets[None]
        values = self.left_flat[flat]
        inv_std = _standardise(values, self.weights)
        dx = self.left_dx_flat[flat]
        dx *= inv_std[:, None]
        return values, dx

    def _window_columns(self, xs, d, shape) -> np.ndarray:
        """Right-image x of the windows, (n, k) float32 (their rows are ``ys + oy``)."""
        # x + ox - (d + a ox + b oy) = (x - d - b oy) + (1 - a) ox, over the window's rows
        # (oy, outer index) and columns (ox, inner index); minus the curvature term
        shape = np.asarray(shape, np.float32)
        per_row = np.multiply.outer(-shape[:, 1], self.steps)
        per_row += (xs - d).astype(np.float32)[:, None]
        per_col = np.multiply.outer(1.0 - shape[:, 0], self.steps)
        columns = (per_row[:, :, None] + per_col[:, None, :]).reshape(len(xs), -1)
        if shape.shape[1] > 2:
            columns -= shape[:, 2:] @ self.quadratic
        return columns

    def window_rows(self, ys) -> np.ndarray:
        """Image rows of the windows, (n, k) float32."""
        return np.add.outer(ys.astype(np.float32), self.oy)

    def zncc(self, left, ys, xs, d, shape, maps_y=None) -> np.ndarray:
        """Window ZNCC of left pixels at their disparities.

        Parameters
        ----------
        left : tuple of (n, k) float32
            The pixels' :meth:`left_windows`.
        ys, xs : (n,) int
            The pixels.
        d : (n,) float32
            Disparity at the pixel, px.
        shape : (n, 2) or (n, 5) float32
            The disparity's gradient (planar window), or its gradient and second derivatives,
            at the pixels (:data:`SHAPE_COLUMNS`).
        maps_y : (n, k) float32, optional
            The pixels' :meth:`window_rows` (computed when not given).

        Returns
        -------
        (n,) float32
            ZNCC in [-1, 1].
        """
        maps_y = self.window_rows(ys) if maps_y is None else maps_y
        right = _sample(self.right, self._window_columns(xs, d, shape), maps_y)
        _standardise(right, self.weights)
        return np.einsum("ij,ij,j->i", left[0], right, self.weights, optimize=True)

    def refine(
        self, left, ys, xs, d, shape, iterations: int, score: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Gauss-Newton refinement of the disparity of left pixels with their own windows.

        Minimises the weighted squared difference of the standardised windows over ``d`` (the
        ``shape`` is kept), with the mean gradient of both images (ESM); steps are
        clipped to half a pixel.

        Parameters
        ----------
        left, ys, xs, d, shape
            As in :meth:`zncc`; ``d`` is the starting disparity, px.
        iterations : int
            Gauss-Newton steps.
        score : bool
            Also return the ZNCC at the result.

        Returns
        -------
        d : (n,) float32
            Refined disparity, px.
        zncc : (n,) float32 or None
            Window ZNCC at ``d`` (None unless ``score``).
        """
        left_values, left_dx = left
        maps_y = self.window_rows(ys)
        d = d.astype(np.float32).copy()
        for _ in range(iterations):
            maps_x = self._window_columns(xs, d, shape)
            err = _sample(self.right, maps_x, maps_y)
            grad = _sample(self.right_dx, maps_x, maps_y, cv2.INTER_LINEAR)
            grad *= _standardise(err, self.weights)[:, None]
            grad += left_dx  # twice the mean gradient; d(left - right(x - d)) / dd = right_x
            np.subtract(left_values, err, out=err)
            num = np.einsum("ij,ij,j->i", grad, err, self.weights, optimize=True)
            den = np.einsum("ij,ij,j->i", grad, grad, self.weights, optimize=True)
            d += np.clip(-2.0 * num / np.maximum(den, 1e-6), -0.5, 0.5)
        return d, (self.zncc(left, ys, xs, d, shape, maps_y) if score else None)


def _smoothed(disparity: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised convolution of a disparity field with holes (a Gaussian over valid pixels).

    Returns the smoothed field (h, w) float32, px, and the Gaussian weight of valid pixels
    (h, w) float32 in [0, 1].
    """
    valid = np.isfinite(disparity)
    weight = cv2.GaussianBlur(valid.astype(np.float32), (0, 0), sigma)
    smooth = cv2.GaussianBlur(np.where(valid, disparity, 0.0).astype(np.float32), (0, 0), sigma)
    smooth /= np.maximum(weight, 1e-6)
    return smooth, weight


#: The largest disparity curvature a window follows, px per px squared. The default stereo
#: neutral's lips and nose reach 0.07-0.1; beyond 0.15 the smoothing reached across a depth
#: step (the plate of the step scene keeps its RMS only with this cap: 1.4 mm without).
_MAX_CURVATURE = 0.15


def _disparity_shape(disparity: np.ndarray, sigma: float, curvature: bool) -> np.ndarray:
    """Gradient (and second derivatives) of the disparity field, defined next to holes too.

    Central differences of the field smoothed by normalised convolution: the gradient with
    ``sigma``, the second derivatives with ``2 sigma`` (they amplify the disparity's noise; a
    Gaussian keeps the second derivative of a quadratic field, so the curvature of a ridge
    whose planar-window disparity is flattened is still measured right). Measured on the
    default stereo neutral (synth02): ``sigma`` for both leaves the median depth error at
    0.113 mm and the RMS at 0.457 mm, ``2 sigma`` for the curvature at 0.109 / 0.454 mm
    (planar windows: 0.109 / 0.467).

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    sigma : float
        The Gaussian of the gradient, px.
    curvature : bool
        Also the second derivatives (else only the gradient: planar windows).

    Returns
    -------
    (h, w, 5) or (h, w, 2) float32
        Per pixel the columns of :data:`SHAPE_COLUMNS` (px per px, px per px squared); the
        second derivatives are 0 where less than half of the wider Gaussian covers valid
        pixels, and where one exceeds :data:`_MAX_CURVATURE` (next to a depth step, where the
        smoothing mixes two surfaces).
    """
    smooth, _ = _smoothed(disparity, sigma)
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=1, scale=0.5)
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=1, scale=0.5)
    if not curvature:
        return np.stack([gx, gy], axis=-1)
    wide, weight = _smoothed(disparity, 2.0 * sigma)
    trust = (weight > 0.5).astype(np.float32)
    gxx = cv2.Sobel(wide, cv2.CV_32F, 2, 0, ksize=1) * trust
    gyy = cv2.Sobel(wide, cv2.CV_32F, 0, 2, ksize=1) * trust
    gxy = cv2.Sobel(cv2.Sobel(wide, cv2.CV_32F, 1, 0, ksize=1), cv2.CV_32F, 0, 1, ksize=1)
    gxy *= 0.25 * trust
    # the largest of the three per pixel, one image at a time (numpy's reduction over a short
    # last axis is about 10 times slower; max is exact, so the same answer)
    steep = np.maximum(np.maximum(np.abs(gxx), np.abs(gxy)), np.abs(gyy)) > _MAX_CURVATURE
    out = np.stack([gx, gy, gxx, gxy, gyy], axis=-1)
    out[steep, 2:] = 0.0
    return out


def _refine_patches(
    disparity: np.ndarray,
    matcher: _PatchMatcher,
    iterations: int,
    slope_sigma: float,
    curvature: bool,
) -> np.ndarray:
    """Refine every valid disparity with its own slanted window; drop those that move > 1 px.

    The windowed refinement (:func:`~scan2morph.scan.stereo.windowed._refine_subpixel`)
    averages the steps of a neighbourhood; this one fits each pixel's own small window
    (``patch_radius_px``), which sharpens the disparity at curved and slanted skin (measured:
    median depth error 0.15 -> 0.11 mm).

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    matcher : _PatchMatcher
        The rectified pair's slanted-window matcher.
    iterations : int
        Gauss-Newton steps.
    slope_sigma : float
        Smoothing of the disparity gradient that slants the windows, px.
    curvature : bool
        Bend the windows with the disparity's curvature too (:func:`_disparity_shape`).

    Returns
    -------
    (h, w) float32
    """
    ys, xs = np.nonzero(np.isfinite(disparity))
    if ys.size == 0:
        return disparity
    shape = _disparity_shape(disparity, slope_sigma, curvature)[ys, xs]
    d0 = disparity[ys, xs]
    left = matcher.left_windows(ys, xs)
    d, _ = matcher.refine(left, ys, xs, d0, shape, iterations, score=False)
    out = np.full_like(disparity, np.nan)
    out[ys, xs] = np.where(np.abs(d - d0) <= 1.0, d, np.nan)
    return out


def _extrapolate(
    disparity: np.ndarray, shape: np.ndarray, ys: np.ndarray, xs: np.ndarray
) -> np.ndarray:
    """Disparity of pixels predicted by the planes of their valid 8-neighbours.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    shape : (h, w, 2 or 5) float32
        Its shape (:func:`_disparity_shape`); the gradient is used.
    ys, xs : (n,) int
        The pixels.

    Returns
    -------
    (n,) float32
        The mean of ``d(q) + g(q) . (p - q)`` over the valid neighbours ``q`` of each pixel
        ``p``, px; NaN where there is none.
    """
    h, w = disparity.shape
    total = np.zeros(ys.size, np.float32)
    count = np.zeros(ys.size, np.int32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == 0 and dx == 0:
                continue
            qy, qx = np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)
            pred = disparity[qy, qx] - shape[qy, qx, 0] * dx - shape[qy, qx, 1] * dy
            ok = np.isfinite(pred)
            total += np.where(ok, pred, 0.0)
            count += ok
    return np.where(count > 0, total / np.maximum(count, 1), np.nan).astype(np.float32)


#: Offsets of the growth's local search around the extrapolated disparity, px.
_GROW_SEARCH_PX = (-1.0, -0.5, 0.0, 0.5, 1.0)


def _grow(
    disparity: np.ndarray,
    matcher: _PatchMatcher,
    allowed: np.ndarray,
    rounds: int,
    min_zncc: float,
    max_change_px: float,
    iterations: int,
    slope_sigma: float,
    curvature: bool,
) -> np.ndarray:
    """Extend the valid disparity into unmatched neighbours, verified by their own windows.

    Each round, every unmatched ``allowed`` pixel with at least two valid 8-neighbours gets
    the disparity its neighbours' planes predict (:func:`_extrapolate`), the best of a local
    search within +-1 px (window ZNCC) and ``iterations`` Gauss-Newton steps of its slanted
    window; it is kept when its ZNCC reaches ``min_zncc`` and it stayed within
    ``max_change_px`` of the prediction. SGBM's fronto-parallel blocks miss much of the steep
    skin (foreshortened in one view) next to occlusions; the slanted window recovers it. The
    strict validation (:func:`_validate`) follows.

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified disparity, px; NaN where invalid.
    matcher : _PatchMatcher
        The rectified pair's slanted-window matcher.
    allowed : (h, w) bool
        Pixels that may be grown (textured, inside the left image).
    rounds : int
        Growth rounds (each reaches 1 px farther).
    min_zncc : float
        Least window ZNCC of a grown pixel.
    max_change_px : float
        Largest departure of a grown pixel from its predicted disparity, px.
    iterations : int
        Gauss-Newton steps per grown pixel.
    slope_sigma : float
        Smoothing of the disparity gradient, px.
    curvature : bool
        Bend the windows with the disparity's curvature too.

    Returns
    -------
    (h, w) float32
    """
    d = disparity.copy()
    for _ in range(rounds):
        valid = np.isfinite(d)
        neighbours = cv2.filter2D(
            valid.astype(np.uint8), -1, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT
        )
        ys, xs = np.nonzero(~valid & allowed & (neighbours >= 2))
        if ys.size == 0:
            break
        field = _disparity_shape(d, slope_sigma, curvature)
        d0, shape = _extrapolate(d, field, ys, xs), field[ys, xs]
        left, maps_y = matcher.left_windows(ys, xs), matcher.window_rows(ys)
        best_z = np.full(ys.size, -np.inf, np.float32)
        best_d = d0.copy()
        for offset in _GROW_SEARCH_PX:
            z = matcher.zncc(left, ys, xs, d0 + offset, shape, maps_y)
            better = z > best_z
            best_z = np.where(better, z, best_z)
            best_d = np.where(better, d0 + offset, best_d)
        grown, z = matcher.refine(left, ys, xs, best_d, shape, iterations)
        keep = (z >= min_zncc) & (np.abs(grown - d0) <= max_change_px)
        if not keep.any():
            break
        d[ys[keep], xs[keep]] = grown[keep]
    return d


def _validate(
    disparity: np.ndarray,
    matcher: _PatchMatcher,
    min_zncc: float,
    disp_right: np.ndarray,
    lr_max_diff_px: float,
    textured: np.ndarray,
    slope_sigma: float,
    curvature: bool,
) -> np.ndarray:
    """Keep the pixels whose own slanted window matches and that the right view confirms.

    Replaces the erosion of every hole border: a pixel is dropped for its own evidence only,
    when its window ZNCC (:class:`_PatchMatcher`) is below ``min_zncc`` (-1: no check), when
    the right view's SGBM disparity at its match disagrees by more than ``lr_max_diff_px``
    (the left-right check again, now for refined and grown pixels; where the right view has no
    disparity the window decides alone), or when it is not ``textured`` itself (an untextured
    background pixel next to a silhouette matches the silhouette's edge).

    Parameters
    ----------
    disparity : (h, w) float32
        Rectified left disparity, px; NaN where invalid.
    matcher : _PatchMatcher
        The rectified pair's slanted-window matcher.
    min_zncc : float
        Least window ZNCC.
    disp_right : (h, w) float32
        The right view's disparity (``-d`` for the match ``xl = xr + d``), px; NaN where none.
    lr_max_diff_px : float
        Largest accepted ``|d_left + d_right|``, px.
    textured : (h, w) bool
        Pixels with texture of their own (the grey-level std within a small window).
    slope_sigma : float
        Smoothing of the disparity gradient, px.
    curvature : bool
        Bend the windows with the disparity's curvature too.

    Returns
    -------
    (h, w) float32
    """
    ys, xs = np.nonzero(np.isfinite(disparity) & textured)
    out = np.full_like(disparity, np.nan)
    if ys.size == 0:
        return out
    d = disparity[ys, xs]
    keep = np.ones(ys.size, bool)
    if min_zncc > -1.0:
        shape = _disparity_shape(disparity, slope_sigma, curvature)[ys, xs]
        left = matcher.left_windows(ys, xs)
        keep &= matcher.zncc(left, ys, xs, d, shape) >= min_zncc
    xr = np.clip(np.rint(xs - d).astype(np.int64), 0, disparity.shape[1] - 1)
    keep &= ~(np.abs(d + disp_right[ys, xr]) > lr_max_diff_px)  # NaN (no match) passes
    out[ys[keep], xs[keep]] = d[keep]
    return out
