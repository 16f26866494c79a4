"""Small holes of a range image filled by Williams' matte-blur filter (Yano-Harada section 3.1,
:func:`fill_holes`), in all three coordinates with one matte, so that a rigid motion of the data
moves the result with it.

Hole filling follows the algorithm the paper takes from L. Williams (1990), "3D paint":

0. the surface array holds the range data, with the missing values set to 0;
1. a matte array is 1 where range data exist and 0 in the gaps;
2. around the gaps, matte and surface are blurred with a small kernel;
3. where the blurred matte exceeds a threshold, the gap sample becomes blurred surface divided
   by blurred matte and its matte becomes 1;
4. steps 2-3 repeat until no gap is left.

Step 3's ratio is a normalised convolution, i.e. a weighted mean of the valid neighbours. On a
tilted or curved surface that mean lags one pixel behind the front (the neighbours all lie on
one side), which costs a pixel pitch times the slope, e.g. 0.5 mm for the in-plane coordinates
of a 0.5 mm/px scan. With ``trend_degree`` 1 or 2 (default 2) each hole's surface is also fitted
by a polynomial in pixel coordinates over the valid rim around it, and step 3 subtracts the
polynomial's Taylor expansion over the same weights (first and second matte-weighted moments of
the kernel), so that the filled value is exact for surfaces that are linear (degree 1) or
quadratic (degree 2) in the pixel coordinates. ``trend_degree=0`` is the paper's filter verbatim.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from scipy import ndimage

from scan2morph.errors import InputError
from scan2morph.scan.settings import (
    DEFAULT_REPAIR,
    PARAMS_SOURCE,
    check_float,
    check_int,
    check_xyz,
    neighbour_offsets,
)

#: Width (px, chessboard distance) of the valid rim around a hole used to fit its trend.
_RIM_PX = 3
#: Condition-number guard for the per-hole trend fits (6 x 6 normal equations, scaled basis).
_FIT_RCOND = 1e-10
#: A hole whose rim the trend fits worse than this (RMS 3D residual, mm) is filled without the
#: trend terms: its rim spans a depth edge, where a polynomial would extrapolate nonsense.
_TREND_MAX_RMS_MM = 1.0


def _binomial_kernel(size: int) -> np.ndarray:
    """1D binomial kernel of odd ``size``, sum 1 (a small Gaussian)."""
    k = np.array([1.0])
    for _ in range(size - 1):
        k = np.convolve(k, [1.0, 1.0])
    return k / k.sum()


def _sorted_unique(keys: np.ndarray) -> np.ndarray:
    """``np.unique`` of a 1-D integer array (sorted, each value once), by a sort: numpy 2's
    hash-based ``unique`` is several times slower on the million rim keys of a depth camera's
    speckled holes. The keys come nearly sorted (98 % of neighbours in order, hole by hole),
    which the stable sort (a merge sort of runs) takes in 0.02 s against the default
    quicksort's 0.09 s; integers sort to the same array either way."""
    keys = np.sort(keys, kind="stable")
    return keys[np.concatenate(([True], keys[1:] != keys[:-1]))] if keys.size else keys


def _hole_trends(
    pad: np.ndarray,
    valid_pad: np.ndarray,
    gap_idx: np.ndarray,
    gap_lab: np.ndarray,
    n_lab: int,
    wp: int,
    degree: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit each hole's surface by a polynomial over its valid rim; return its derivatives.

    Degree 0 fits nothing and rejects nothing.

    Parameters
    ----------
    pad : (Hp * Wp, 3) float64
        The padded range image, row-major, mm; NaN where there is no data.
    valid_pad : (Hp * Wp,) bool
        Pixels of ``pad`` with data.
    gap_idx : (n_gap,) int
        Flat index of every gap pixel in ``pad``.
    gap_lab : (n_gap,) int
        Hole of every gap pixel, 0..n_lab-1.
    n_lab : int
        Number of holes.
    wp : int
        Padded width ``Wp``, px.
    degree : {0, 1, 2}
        Degree of the polynomial in the pixel coordinates; lowered per hole whose rim has
        fewer than twice as many pixels as unknowns.

    Returns
    -------
    grad : (n_gap, 3, 2) float64
        Gradient (d/du, d/dv) of each coordinate at each gap pixel, mm/px (row = v, column
        = u).
    hess : (n_gap, 3, 3) float64
        Hessian entries (uu, uv, vv) of each coordinate at each gap pixel, mm/px^2.
    rejected : (n_lab,) bool
        Holes whose rim the fit misses by more than 1 mm RMS (or that have no rim); their
        derivatives are 0.
    """
    n_gap = gap_idx.size
    grad = np.zeros((n_gap, 3, 2))
    hess = np.zeros((n_gap, 3, 3))
    if degree == 0:
        return grad, hess, np.zeros(n_lab, dtype=bool)
    offs, _ = neighbour_offsets(wp, _RIM_PX, centre=False)
    # (hole, rim pixel) pairs; a pixel between two holes serves both fits.
    cand = gap_idx[:, None] + offs[None, :]
    lab = np.broadcast_to(gap_lab[:, None], cand.shape)
    ok = valid_pad[cand]
    key = _sorted_unique(lab[ok].astype(np.int64) * pad.shape[0] + cand[ok])
    pl, pp = np.divmod(key, pad.shape[0])
    pv, pu = np.divmod(pp, wp)
    gv, gu = np.divmod(gap_idx, wp)
    # each hole's centroid and size, to centre and scale the basis
    cnt = np.bincount(gap_lab, minlength=n_lab)
    cu = np.bincount(gap_lab, gu, minlength=n_lab) / np.maximum(cnt, 1)
    cv = np.bincount(gap_lab, gv, minlength=n_lab) / np.maximum(cnt, 1)
    scale = np.sqrt(np.maximum(cnt, 1)) / 2.0 + _RIM_PX
    a = (pu - cu[pl]) / scale[pl]
    b = (pv - cv[pl]) / scale[pl]
    basis = np.stack([np.ones_like(a), a, b, a * a, a * b, b * b], axis=1)  # (P, 6)
    n_terms = np.bincount(pl, minlength=n_lab)
    # fewer rim points than twice the unknowns: lower the degree for that hole
    deg = np.where(n_terms >= 12, degree, np.where(n_terms >= 6, 1, 0))
    used = np.array([1, 1, 1, 2, 2, 2])[None, :] <= np.maximum(deg, 0)[:, None]  # (L, 6)
    used[:, 0] = True
    basis = basis * used[pl]
    ata = np.zeros((n_lab, 6, 6))
    atb = np.zeros((n_lab, 6, 3))
    rim = pad[pp]
    # the columns contiguous (the same products, a third of the time)
    cols, rim_cols = np.ascontiguousarray(basis.T), np.ascontiguousarray(rim.T)
    for i in range(6):  # each entry summed over the rim pixels in order, as np.add.at does
        for j in range(i, 6):
            ata[:, i, j] = ata[:, j, i] = np.bincount(pl, cols[i] * cols[j], n_lab)
        for c in range(3):
            atb[:, i, c] = np.bincount(pl, cols[i] * rim_cols[c], n_lab)
    li, ji = np.nonzero(~used)
    ata[li, ji, ji] = 1.0  # unused terms solve to 0
    coef = np.linalg.pinv(ata, rcond=_FIT_RCOND) @ atb  # (L, 6, 3)
    resid2 = np.sum((pad[pp] - np.einsum("pk,pkc->pc", basis, coef[pl])) ** 2, axis=1)
    fit_rms = np.sqrt(np.bincount(pl, resid2, minlength=n_lab) / np.maximum(n_terms, 1))
    rejected = (n_terms == 0) | (fit_rms > _TREND_MAX_RMS_MM)
    coef[rejected] = 0.0
    # derivatives at the gap pixels, back to pixel units
    c = coef[gap_lab]  # (n_gap, 6, 3)
    s = scale[gap_lab][:, None]
    a = ((gu - cu[gap_lab]) / scale[gap_lab])[:, None]
    b = ((gv - cv[gap_lab]) / scale[gap_lab])[:, None]
    grad[:, :, 0] = (c[:, 1] + 2 * c[:, 3] * a + c[:, 4] * b) / s
    grad[:, :, 1] = (c[:, 2] + c[:, 4] * a + 2 * c[:, 5] * b) / s
    hess[:, :, 0] = 2 * c[:, 3] / s**2
    hess[:, :, 1] = c[:, 4] / s**2
    hess[:, :, 2] = 2 * c[:, 5] / s**2
    return grad, hess, rejected


def fill_holes(
    xyz: np.ndarray,
    max_hole_px: int = DEFAULT_REPAIR["max_hole_px"],
    kernel_px: int = DEFAULT_REPAIR["fill_kernel_px"],
    threshold: float = DEFAULT_REPAIR["fill_threshold"],
    max_iter: int = DEFAULT_REPAIR["fill_max_iter"],
    *,
    trend_degree: int = 2,
    max_edge_hole_px: int = DEFAULT_REPAIR["max_edge_hole_px"],
    source: str = "repair",
) -> tuple[np.ndarray, dict[str, Any]]:
    """Fill the small holes of a range image by Williams' matte-blur filter.

    A hole is an 8-connected component of NaN pixels that does not touch the image border
    (components that do are background). Holes of at most ``max_hole_px`` pixels are filled
    (see the module docstring for the filter); larger ones stay NaN and are reported, as do
    holes the filter could not close within ``max_iter`` iterations.

    Parameters
    ----------
    xyz : (H, W, 3) float ndarray, mm
        Range image, NaN where there is no data. Not modified.
    max_hole_px : int
        Largest hole area filled, pixels.
    kernel_px : int
        Odd side length of the binomial blur kernel, pixels.
    threshold : float
        Blurred-matte level in (0, 1) above which a gap pixel is filled. Progress is guaranteed
        below the kernel's weight on one adjacent row (0.25 for a 3 px kernel).
    max_iter : int
        Largest number of blur passes.
    trend_degree : {0, 1, 2}
        Degree of the per-hole polynomial whose Taylor terms correct step 3 (0: the paper's
        filter as is; 2: exact for surfaces quadratic in the pixel coordinates).
    max_edge_hole_px : int
        Largest hole filled whose rim the trend fits worse than 1 mm RMS, pixels. Such a rim
        spans a depth edge or a strongly curved side of the face (the chin over the neck, the
        side of the face a second stereo camera does not see), where the filter, left without
        its trend terms, would bridge the hole with a made-up surface: small ones (a pupil, a
        nostril pixel) are filled, larger ones stay holes. With ``trend_degree`` 0 no rim is
        fitted and every hole up to ``max_hole_px`` is filled.
    source : str
        Names the data in ``xyz`` errors (a file or ``subject/take``); parameter errors name
        the config section ``repair``.

    Returns
    -------
    xyz_filled : (H, W, 3) float64 ndarray, mm
        Copy of ``xyz`` with the small holes filled.
    report : dict
        ``n_holes`` (int, holes found), ``n_filled`` (int), ``filled_px`` (int),
        ``unfilled_holes`` (list of int, areas in px of the holes left, largest first),
        ``largest_unfilled_px`` (int, 0 if none), ``n_iter`` (int, blur passes run),
        ``n_trend_rejected`` (int, holes whose rim the polynomial fits worse than 1 mm RMS, e.g.
        across a depth edge: filled without trend terms up to ``max_edge_hole_px``, else left
        and listed in ``unfilled_holes``) and ``filled`` ((H, W) bool, pixels that received
        values).

    Raises
    ------
    InputError
        If ``xyz`` is not an (H, W, 3) float array with some valid pixel, or a parameter is
        out of range.
    """
    arr, valid = check_xyz(xyz, source)
    max_hole_px = check_int(max_hole_px, "max_hole_px", PARAMS_SOURCE, minimum=1)
    max_edge_hole_px = check_int(max_edge_hole_px, "max_edge_hole_px", PARAMS_SOURCE, minimum=0)
    kernel_px = check_int(kernel_px, "kernel_px", PARAMS_SOURCE, minimum=3, odd=True)
    threshold = check_float(threshold, "threshold", PARAMS_SOURCE, upper=1.0)
    max_iter = check_int(max_iter, "max_iter", PARAMS_SOURCE, minimum=1)
    if trend_degree not in (0, 1, 2) or isinstance(trend_degree, bool):
        raise InputError(PARAMS_SOURCE, f"trend_degree: expected 0, 1 or 2, got {trend_degree!r}")
    labels, area, hole = _label_holes(valid)
    target = hole & (area <= max_hole_px)  # the small holes: to fill
    report: dict[str, Any] = {"n_holes": int(hole.sum()), "n_iter": 0, "n_trend_rejected": 0}
    filled = np.zeros(valid.shape, bool)
    if target[labels].any():
        gaps = _gap_pixels(arr, labels, target, kernel_px)
        grad, hess, rejected = _hole_trends(
            gaps.pad, gaps.valid_pad, gaps.idx, gaps.lab, gaps.hole_ids.size, gaps.wp, trend_degree
        )
        report["n_trend_rejected"] = int(rejected.sum())
        # a hole across a depth edge (its rim fits no trend) is filled only when small
        unfit = rejected & (area[gaps.hole_ids] > max_edge_hole_px)
        if unfit.any():
            target[gaps.hole_ids[unfit]] = False
            keep = ~unfit[gaps.lab]
            gaps, grad, hess = gaps.subset(keep), grad[keep], hess[keep]
        surf, todo, report["n_iter"] = _williams_fill(
            gaps, grad, hess, kernel_px, threshold, max_iter
        )
        failed = _store_closed_holes(arr, filled, gaps, surf, todo)
        target[failed] = False
    report.update(_fill_report(hole, target, area, filled))
    return arr, report


def _label_holes(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Label the 8-connected gaps of a range image and tell holes from background.

    Parameters
    ----------
    valid : (H, W) bool
        Pixels with range data.

    Returns
    -------
    labels : (H, W) int
        Gap component of every pixel, 1..n; 0 on the data.
    area : (n + 1,) int
        Area of every component, px (entry 0: the data).
    hole : (n + 1,) bool
        Components that do not touch the image border (the others are background); False
        for entry 0.
    """
    labels, n_comp = ndimage.label(~valid, structure=np.ones((3, 3), bool))
    area = np.bincount(labels.ravel(), minlength=n_comp + 1)
    border = np.zeros(n_comp + 1, bool)
    for edge in (labels[0], labels[-1], labels[:, 0], labels[:, -1]):
        border[edge] = True
    border[0] = True  # label 0 is the valid data
    return labels, area, ~border


class _Gaps(NamedTuple):
    """The pixels of the holes to fill, on a NaN-padded flat copy of the range image.

    Attributes
    ----------
    pad : (Hp * Wp, 3) float64
        The range image padded by ``rp`` px on each side, row-major, mm; NaN where there is
        no data.
    valid_pad : (Hp * Wp,) bool
        Pixels of ``pad`` with data.
    wp : int
        Padded width ``Wp``, px.
    y, x : (n,) int
        Image row and column of every gap pixel, px.
    idx : (n,) int
        Flat index of every gap pixel in ``pad``.
    lab : (n,) int
        Hole of every gap pixel, 0..L-1.
    hole_ids : (L,) int
        Component label (of :func:`_label_holes`) of every hole.
    """

    pad: np.ndarray
    valid_pad: np.ndarray
    wp: int
    y: np.ndarray
    x: np.ndarray
    idx: np.ndarray
    lab: np.ndarray
    hole_ids: np.ndarray

    def subset(self, keep: np.ndarray) -> _Gaps:
        """The gap pixels where ``keep`` ((n,) bool) is True (``hole_ids`` unchanged)."""
        return self._replace(y=self.y[keep], x=self.x[keep], idx=self.idx[keep], lab=self.lab[keep])


def _gap_pixels(arr: np.ndarray, labels: np.ndarray, target: np.ndarray, kernel_px: int) -> _Gaps:
    """Collect the pixels of the target holes on a padded copy of the range image.

    Parameters
    ----------
    arr : (H, W, 3) float64
        Range image, mm; NaN where there is no data.
    labels : (H, W) int
        Gap components of :func:`_label_holes`.
    target : (n + 1,) bool
        Components to fill.
    kernel_px : int
        Odd side of the blur kernel, px; the padding covers it and the trend's rim.

    Returns
    -------
    _Gaps
        The padded image and the target holes' pixels, numbered hole by hole.
    """
    r = kernel_px // 2
    rp = max(r, _RIM_PX)
    wp = arr.shape[1] + 2 * rp
    pad = np.pad(arr, ((rp, rp), (rp, rp), (0, 0)), constant_values=np.nan)
    pad = pad.reshape(-1, 3)
    valid_pad = ~np.isnan(pad[:, 0])
    gy, gx = np.nonzero(target[labels])
    gap_idx = (gy + rp) * wp + (gx + rp)
    # consecutive hole ids 0..L-1 for the fits
    hole_ids, gap_lab = np.unique(labels[gy, gx], return_inverse=True)
    return _Gaps(pad, valid_pad, wp, gy, gx, gap_idx, gap_lab, hole_ids)


def _williams_fill(
    gaps: _Gaps,
    grad: np.ndarray,
    hess: np.ndarray,
    kernel_px: int,
    threshold: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Williams' steps 0-4, with the Taylor terms of each hole's trend, at the gap pixels.

    Parameters
    ----------
    gaps : _Gaps
        The padded image and the n gap pixels to fill.
    grad : (n, 3, 2) float64
        Trend gradient of each coordinate at each gap pixel, (d/du, d/dv), mm/px.
    hess : (n, 3, 3) float64
        Trend Hessian entries (uu, uv, vv) at each gap pixel, mm/px^2.
    kernel_px : int
        Odd side of the binomial blur kernel, px.
    threshold : float
        Blurred-matte level above which a gap pixel is filled, in (0, 1).
    max_iter : int
        Largest number of blur passes.

    Returns
    -------
    surf : (Hp * Wp, 3) float64
        The padded surface array, mm: data, filled gap pixels, 0 at the gaps left.
    todo : (m,) int
        Indices into the gap pixels the filter could not fill.
    n_iter : int
        Blur passes run.
    """
    # Step 0 and 1: surface with gaps at 0, matte 1 on data
    surf = np.where(gaps.valid_pad[:, None], gaps.pad, 0.0)
    matte = gaps.valid_pad.astype(np.float64)
    k1 = _binomial_kernel(kernel_px)
    kern = np.outer(k1, k1).ravel()  # (K,)
    offs, dyx = neighbour_offsets(gaps.wp, kernel_px // 2, centre=True)
    d = dyx[:, ::-1].astype(np.float64)  # (K, 2) as (du, dv)
    d2 = np.stack([d[:, 0] ** 2, 2 * d[:, 0] * d[:, 1], d[:, 1] ** 2], axis=1) / 2

    gap_idx = gaps.idx
    todo = np.arange(gap_idx.size)
    n_iter = 0
    for it in range(max_iter):
        # Step 2: blur matte and surface at the remaining gap pixels only
        nb = gap_idx[todo, None] + offs[None, :]
        wgt = matte[nb] * kern[None, :]  # (n, K)
        m0 = wgt.sum(axis=1)
        ready = m0 > threshold
        n_iter = it + 1
        if not ready.any():
            break
        sel, wgt, nb, m0 = todo[ready], wgt[ready], nb[ready], m0[ready]
        blur = np.einsum("nk,nkc->nc", wgt, surf[nb])
        # Taylor terms of the hole's trend over the same weights (zero if degree 0)
        m1 = wgt @ d  # (n, 2)
        m2 = wgt @ d2  # (n, 3)
        corr = np.einsum("ncj,nj->nc", grad[sel], m1) + np.einsum("ncj,nj->nc", hess[sel], m2)
        # Step 3: replace by blurred surface / blurred matte; matte becomes 1
        surf[gap_idx[sel]] = (blur - corr) / m0[:, None]
        matte[gap_idx[sel]] = 1.0
        todo = todo[~ready]
        if todo.size == 0:  # Step 4: until no gap is left
            break
    return surf, todo, n_iter


def _store_closed_holes(
    arr: np.ndarray, filled: np.ndarray, gaps: _Gaps, surf: np.ndarray, todo: np.ndarray
) -> np.ndarray:
    """Copy the holes the filter closed into ``arr`` and mark them in ``filled`` (in place).

    Parameters
    ----------
    arr : (H, W, 3) float64
        Range image, mm; receives the filled values.
    filled : (H, W) bool
        Set True at the pixels filled.
    gaps : _Gaps
        The gap pixels.
    surf : (Hp * Wp, 3) float64
        The padded surface array of :func:`_williams_fill`, mm.
    todo : (m,) int
        Indices into the gap pixels the filter could not fill.

    Returns
    -------
    failed : (k,) int
        Component labels of the holes left: a hole the filter could not close stays NaN as a
        whole.
    """
    failed_lab = np.unique(gaps.lab[todo])
    ok = ~np.isin(gaps.lab, failed_lab)
    arr[gaps.y[ok], gaps.x[ok]] = surf[gaps.idx[ok]]
    filled[gaps.y[ok], gaps.x[ok]] = True
    return gaps.hole_ids[failed_lab]


def _fill_report(
    hole: np.ndarray, target: np.ndarray, area: np.ndarray, filled: np.ndarray
) -> dict[str, Any]:
    """The counts of :func:`fill_holes`' report (see there for the keys).

    Parameters
    ----------
    hole : (n + 1,) bool
        Gap components that are holes.
    target : (n + 1,) bool
        Holes filled.
    area : (n + 1,) int
        Area of every component, px.
    filled : (H, W) bool
        Pixels filled.

    Returns
    -------
    dict
        ``n_filled``, ``filled_px``, ``unfilled_holes`` (areas in px, largest first),
        ``largest_unfilled_px`` and ``filled``.
    """
    left = np.flatnonzero(hole & ~target)
    unfilled = sorted((int(a) for a in area[left]), reverse=True)
    return {
        "n_filled": int(target.sum()),
        "filled_px": int(filled.sum()),
        "unfilled_holes": unfilled,
        "largest_unfilled_px": unfilled[0] if unfilled else 0,
        "filled": filled,
    }


__all__ = ["fill_holes"]
