"""Image correlation in template space: a measured displacement field with a confidence, and
its fusion into a smooth correction that falls back to the template fit where the skin shows
nothing to correlate.

The measurement is dense inverse-search optical flow (:func:`cv2.DISOpticalFlow`, Kroeger et
al. 2016) between contrast-normalised images (a local high-pass divided by the local contrast
scale of the whole face), so that the slowly varying shading, which changes when the face
deforms, does not count. Each measured vector is trusted by

- the local texture: the high-pass energy against the image noise (flat skin: no weight);
- forward-backward consistency (the flow from the take back to the neutral undoes it);
- the correlation (ZNCC) of the two images' high-passes after the displacement.

The fusion minimises, over the correction field ``f`` on the grid,
``sum_g w_g |f_g - m_g|^2 + lambda sum_(g~h) |f_g - f_h|^2 + sum_g mu^2 / (w_g + mu) |f_g|^2
+ sum_l k_l |f_(g_l)|^2``: the measurements ``m`` weighted by their confidence, a membrane
(elastic) term, a weak pull to zero where nothing is measured (the template fit:
``sqrt(lambda / mu)`` grid pixels is the distance over which a measured correction fades) and the fiducials,
where the fit put the clicked landmarks, as soft constraints weighted by the click precision.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np
from scipy import sparse
from scipy.ndimage import gaussian_filter
from scipy.sparse.linalg import splu

from scan2morph.errors import InputError
from scan2morph.geometry import finite_points, lengths_2d
from scan2morph.refine.memo import shared

#: Gaussian scale of the ZNCC window that checks each flow vector (:func:`measure_flow`), px.
ZNCC_WINDOW_PX = 3.0
#: Gaussian scale of the structure tensor's average (:func:`aperture`), px: the correlation's
#: own window.
APERTURE_RHO_PX = ZNCC_WINDOW_PX
#: A direction's texture counts against this many times the noise's own gradient energy
#: (:func:`aperture`). Larger is more anisotropic: on the default cohort (3 iterations, one
#: projector for all channels) 1 / 4 / 16 left the worst take at 1.07x / 1.16x / 1.13x of the
#: isotropic fusion's, for the same gains (docs/methods.md).
APERTURE_NOISE = 1.0
#: Fewest textured pixels from which :func:`texture_gain` estimates a take's texture gain.
MIN_GAIN_PIXELS = 100
#: A texture gain is shrunk towards 1 by this factor (:func:`texture_gain`): a flow between
#: images 10% apart in contrast loses about 4% of its precision.
GAIN_BAND = 1.1
#: Below this texture gain the moving image shows too little of the reference's texture to
#: match it (:func:`measure_flow` measures nothing rather than amplify its noise).
MIN_GAIN = 0.1
#: Coarsest finest-level of the flow's search (:func:`measure_flow`'s ``level``): 2 is a quarter
#: of the resolution; OpenCV quietly searches a small grid at a finer level than asked.
MAX_LEVEL = 2


def high_pass(image: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Local high-pass of an image with missing values, and its local RMS.

    Parameters
    ----------
    image : (rows, columns) float
        NaN where there is no image.
    sigma : float
        Gaussian scale of the local mean, px.

    Returns
    -------
    hp : (rows, columns) float64
        Image minus its local (normalised, masked) Gaussian mean; 0 where missing.
    rms : (rows, columns) float64
        Local RMS of ``hp`` over a Gaussian of ``2 sigma``; 0 where missing.
    """
    mask = np.isfinite(image)
    img = np.where(mask, image, 0.0).astype(np.float64)
    m = mask.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = gaussian_filter(img, sigma) / gaussian_filter(m, sigma)
        hp = np.where(mask, img - mean, 0.0)
        rms = np.sqrt(gaussian_filter(hp**2, 2 * sigma) / gaussian_filter(m, 2 * sigma))
    return hp, np.where(mask, np.nan_to_num(rms), 0.0)


def reference_side(reference: np.ndarray, sigma: float, patch: float, noise: float) -> tuple:
    """What :func:`measure_flow` computes from its reference image alone (the same in every
    round of a refinement): its :func:`high_pass` ``hp`` and ``rms`` (rows, columns), the
    Gaussian (``patch`` px) of ``hp^2`` (the ZNCC's reference energy) and the texture share
    ``rms^2 / (rms^2 + noise^2)`` (``noise`` in grey levels), all float64."""
    hp, rms = high_pass(reference, sigma)
    return hp, rms, gaussian_filter(hp**2, patch), rms**2 / (rms**2 + noise**2)


def aperture(reference: np.ndarray, sigma: float, noise: float) -> np.ndarray:
    """Which directions a flow vector measured on ``reference`` is good for: a projector.

    An image patch measures a displacement only across its texture: along an edge (a brow's,
    the hairline's, a lip's border) it looks the same whatever the slide, and a flow vector
    there says nothing about that component (the aperture problem), however confident its
    texture, consistency and correlation tests. The local structure tensor ``J`` (the
    Gaussian average, over :data:`APERTURE_RHO_PX`, of the high-pass's gradient times its
    transpose) has the texture's energy across each of its eigenvectors; each direction's share
    of it above the noise is ``lambda / (lambda + n)`` with ``n`` :data:`APERTURE_NOISE` times
    the gradient energy of the image noise alone (``noise^2 / 2`` per direction for central
    differences), and the projector keeps each eigenvector with its share over the stronger's:
    ``P = u1 u1^T + (s2 / s1) u2 u2^T``. A well-textured patch gives the identity; an edge
    keeps its normal and, along it, what the noise's own gradient gives (about a fifth at half
    the stated noise).

    Parameters
    ----------
    reference : (rows, columns) float
        Grey image, NaN where missing.
    sigma : float
        High-pass scale, px (:func:`high_pass`).
    noise : float
        Image noise, in the image's units (std).

    Returns
    -------
    (rows, columns, 2, 2) float64
        Symmetric, eigenvalues in [0, 1]; the identity where the image is missing or flat.
    """
    hp, _ = high_pass(reference, sigma)
    gy, gx = np.gradient(hp)
    jxx, jxy, jyy = (gaussian_filter(a, APERTURE_RHO_PX) for a in (gx * gx, gx * gy, gy * gy))
    # the 2 x 2 eigenvalues in closed form; u1 u1^T = (J - l2 I) / (l1 - l2), and
    # P = u1 u1^T + r (I - u1 u1^T)
    mean, half = (jxx + jyy) / 2, np.hypot((jxx - jyy) / 2, jxy)
    strong, weak = mean + half, np.clip(mean - half, 0.0, None)
    big = APERTURE_NOISE * noise**2 / 2
    s1, s2 = strong / (strong + big), weak / (weak + big)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.clip(np.where(s1 > 0, s2 / s1, 1.0), 0.0, 1.0)
        distinct = half > 1e-12 * np.maximum(mean, 1e-300)
        scale = np.where(distinct, (1.0 - ratio) / np.where(distinct, 2 * half, 1.0), 0.0)
    out = np.empty((*hp.shape, 2, 2))
    out[..., 0, 0] = ratio + scale * (jxx - weak)
    out[..., 1, 1] = ratio + scale * (jyy - weak)
    out[..., 0, 1] = out[..., 1, 0] = scale * jxy
    return out


def texture_gain(rms_r: np.ndarray, rms_m: np.ndarray, both: np.ndarray, noise: float) -> float:
    """The moving image's texture contrast over the reference's, where both show the skin.

    The median, over the pixels where the reference's texture stands clear of the noise (its
    local RMS above ``2 noise``), of the ratio of the two local RMS: a take exposed or lit
    darker than its neutral (its grey levels times 0.3) gives about 0.3. Where the take's
    texture sinks towards the noise the ratio reads high (0.3 over a texture of contrast 8 with
    1.5 grey levels of noise: 0.37); taking the noise out (the ratio of the contrast energies
    above ``noise``) reads low instead wherever the image's noise is less than ``noise`` (a
    darkened image's noise is darkened too) and matched the real head's darkened smile worse
    (0.100 / 0.238 of its motion in error, range / RGB-D, against 0.080 / 0.203). The
    estimate's own scatter is a few percent (0.96-1.03 on the default cohort's takes, against
    the ratio of the two images' median contrasts' 0.90-1.17 on a flat-coloured mesh scan), so
    it is shrunk towards 1 by :data:`GAIN_BAND` (in ratio: 1 within it, ``g * GAIN_BAND``
    below, ``g / GAIN_BAND`` above; continuous), which leaves takes of one exposure as they
    were refined.

    Parameters
    ----------
    rms_r, rms_m : (rows, columns) float
        The reference's and the moving image's local RMS (:func:`high_pass`), grey levels.
    both : (rows, columns) bool
        Where both images have a value.
    noise : float
        Image noise, grey levels.

    Returns
    -------
    float
        The gain (>= 0); 1 where fewer than :data:`MIN_GAIN_PIXELS` pixels have texture.
    """
    textured = both & (rms_r > 2.0 * noise)
    if np.count_nonzero(textured) < MIN_GAIN_PIXELS:
        return 1.0
    gain = float(np.median(rms_m[textured] / rms_r[textured]))
    if gain * GAIN_BAND < 1.0:
        return gain * GAIN_BAND
    return gain / GAIN_BAND if gain > GAIN_BAND else 1.0


def _to_u8(hp: np.ndarray, scale: float) -> np.ndarray:
    return np.clip(np.rint(128.0 + hp * scale), 0, 255).astype(np.uint8)


def _warp(field: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """``field`` (rows, cols[, k]) sampled at each grid point plus ``flow`` (rows, cols, 2)."""
    rows, cols = flow.shape[:2]
    gx, gy = np.meshgrid(np.arange(cols, dtype=np.float32), np.arange(rows, dtype=np.float32))
    return cv2.remap(
        field.astype(np.float32),
        gx + flow[..., 0].astype(np.float32),
        gy + flow[..., 1].astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )


def measure_flow(
    reference: np.ndarray,
    moving: np.ndarray,
    sigma: float = 4.0,
    noise: float = 2.0,
    max_fb_px: float = 0.5,
    min_zncc: float = 0.5,
    level: int = 0,
    match_gain: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Displacement ``m`` with ``moving(x + m(x)) ~ reference(x)``, and its confidence.

    Parameters
    ----------
    reference, moving : (rows, columns) float
        Grey images on the same grid, NaN where missing.
    sigma : float
        High-pass scale, px: shading varies more slowly than this.
    noise : float
        Image noise, grey levels (std): texture weaker than this is not trusted.
    max_fb_px : float
        Forward-backward inconsistency beyond which a vector gets no weight, px.
    min_zncc : float
        ZNCC after the displacement below which a vector gets no weight.
    level : int
        Finest pyramid level the flow is searched on (0: the grid itself, 1: half its
        resolution, the preset's default, then upsampled). The skin's texture that carries the
        displacement (pores, freckles) is 1-3 px across, which half the resolution loses.
    match_gain : bool
        Scale the moving image's texture by its gain over the reference's
        (:func:`texture_gain`): two images of one skin taken at other exposures or under a
        weaker or stronger light. Not for images whose contrast differs for another reason (a
        curvature image, where a crease is contrast; a projected speckle against skin).

    Returns
    -------
    flow : (rows, columns, 2) float64
        (x, y) displacement, px.
    confidence : (rows, columns) float64
        In [0, 1]: texture share times the consistency and correlation tests.
    """
    if int(level) != level or not 0 <= level <= MAX_LEVEL:
        raise InputError(
            "refine", f"refine.flow_level: expected an integer 0..{MAX_LEVEL}, got {level!r}"
        )
    # the reference's side is the same in every round of a refinement (and, in a sharing
    # scope, for every take refined against one fit of the neutral)
    hp_r, rms_r, g_rr, texture = shared(
        "flow_reference",
        (reference, sigma, ZNCC_WINDOW_PX, noise),
        lambda: reference_side(reference, sigma, ZNCC_WINDOW_PX, noise),
    )
    hp_m, rms_m = high_pass(moving, sigma)
    both = np.isfinite(reference) & np.isfinite(moving)
    contrast = float(np.median(rms_r[both])) if both.any() else 0.0
    gain = texture_gain(rms_r, rms_m, both, noise) if match_gain else 1.0
    if contrast <= 0 or gain < MIN_GAIN:
        shape = reference.shape
        return np.zeros((*shape, 2)), np.zeros(shape)
    scale = 40.0 / contrast  # the face's median contrast spans +-40 grey levels
    r8, m8 = _to_u8(hp_r, scale), _to_u8(hp_m, scale / gain)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    dis.setFinestScale(int(level))
    fw = dis.calc(r8, m8, None).astype(np.float64)
    bw = dis.calc(m8, r8, None)
    fb = lengths_2d(fw + _warp(bw, fw))
    # ZNCC of the two high-passes over a Gaussian window, after the displacement
    mw = _warp(hp_m, fw).astype(np.float64)
    num = gaussian_filter(hp_r * mw, ZNCC_WINDOW_PX)
    den = np.sqrt(np.maximum(g_rr * gaussian_filter(mw**2, ZNCC_WINDOW_PX), 1e-12))
    zncc = num / den
    ok = both & (fb <= max_fb_px) & (zncc >= min_zncc) & finite_points(fw)
    conf = np.where(ok, texture * np.clip((zncc - min_zncc) / (1 - min_zncc), 0, 1), 0.0)
    return np.where(ok[..., None], fw, 0.0), conf


def fuse(
    measured: np.ndarray,
    weight: np.ndarray,
    inside: np.ndarray,
    smooth: float,
    prior: float,
    anchors: np.ndarray | None = None,
    anchor_weight: float = 0.0,
    coarsen: int = 1,
) -> np.ndarray:
    """The smooth correction field that best fits weighted measurements (see module docstring).

    Parameters
    ----------
    measured : (rows, columns, 2) float
        Measured displacements, px.
    weight : (rows, columns) float
        Their weights (>= 0).
    inside : (rows, columns) bool
        Grid points that carry the field (the template domain); 0 elsewhere.
    smooth : float
        Membrane weight ``lambda`` per grid edge.
    prior : float
        Pull to zero ``mu`` per grid point (> 0 keeps the system definite).
    anchors : (n, 2) int, optional
        Grid (row, column) of the fiducials, pulled to zero with ``anchor_weight`` each.
    coarsen : int
        Solve on a grid this many times coarser (cells sum their weights and average their
        measurements; the same energy on a field linear within a cell), then interpolate
        bilinearly: the correction varies over ``smooth_px`` anyway, and the sparse solve is
        about ``coarsen^3`` times faster.

    Returns
    -------
    (rows, columns, 2) float64
        The correction, px; 0 outside ``inside``.
    """
    return fusion(weight, inside, smooth, prior, anchors, anchor_weight, coarsen)(measured)


def fusion(
    weight: np.ndarray,
    inside: np.ndarray,
    smooth: float,
    prior: float,
    anchors: np.ndarray | None = None,
    anchor_weight: float = 0.0,
    coarsen: int = 1,
) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`fuse` with its system factorised once: a function of the measurements
    (rows, columns, 2) px, for several fields with the same weights (the same arguments)."""
    rows, cols = inside.shape
    if coarsen > 1:
        return _fusion_coarse(weight, inside, smooth, prior, anchors, anchor_weight, int(coarsen))
    idx, lap, pattern, slots, deg = _membrane(inside, smooth)
    w = np.where(inside, weight, 0.0)[inside]
    # the pull to zero acts where nothing is measured (mu^2 / (w + mu): mu at w = 0, vanishing
    # where w >> mu), so that it does not shrink what is measured
    diag = w + prior**2 / (w + prior)
    if anchors is not None and len(anchors):
        a = np.asarray(anchors, dtype=np.int64)
        keep = (a[:, 0] >= 0) & (a[:, 0] < rows) & (a[:, 1] >= 0) & (a[:, 1] < cols)
        ai = idx[a[keep, 0], a[keep, 1]]
        np.add.at(diag, ai[ai >= 0], anchor_weight)
    main = diag + smooth * deg
    if pattern is not None and np.all(main != 0):
        A = pattern.copy()  # the membrane's matrix with this call's diagonal
        A.data[slots] = main
    else:  # a zero (on the diagonal, or smooth) leaves the sum's pattern: built as it is
        A = (sparse.diags(main) + lap).tocsc()
    solve = _factorised(A)

    def apply(measured: np.ndarray) -> np.ndarray:
        out = np.zeros((rows, cols, 2))
        for k in range(2):
            out[..., k][inside] = solve(w * measured[..., k][inside])
        return out

    return apply


def fuse_across(
    fused: np.ndarray,
    across: np.ndarray,
    share: np.ndarray,
    solve: Callable[[np.ndarray], np.ndarray],
    iterations: int,
) -> np.ndarray:
    """The fusion with each vector trusted only across its image's texture.

    With per-vector projectors ``P`` (:func:`aperture`), the fusion's data term becomes
    ``sum_g w_g (f_g - m_g)^T P_g (f_g - m_g)``. Its minimiser is the fixed point of
    ``f = solve(P m + (I - P) f)``: the measured component across the texture, the current
    solution's along it, fused by the same (scalar-weight) system, which is factorised once.

    Parameters
    ----------
    fused : (rows, columns, 2) float
        The start: the fusion with every vector trusted in every direction, px.
    across : (rows, columns, 2) float
        ``P m``: each measured vector's component across its texture, px.
    share : (rows, columns, 2, 2) float
        ``P`` (a weighted mean of projectors where several channels measured).
    solve : callable
        The round's :func:`fusion`: a measurement field (rows, columns, 2) -> its correction.
    iterations : int
        Fixed-point steps (>= 0).

    Returns
    -------
    (rows, columns, 2) float64
        The correction, px.
    """
    f = np.asarray(fused, dtype=np.float64)
    for _ in range(int(iterations)):
        f = solve(across + f - np.einsum("rcij,rcj->rci", share, f))
    return f


def _membrane(inside: np.ndarray, smooth: float) -> tuple:
    """What :func:`fuse`'s system takes from the grid alone (the same in every round of a
    refinement, and for every take refined against one fit of the neutral): ``(idx, lap,
    pattern, slots, deg)``, the unknowns' numbers on the grid (-1 outside ``inside``), the
    membrane's off-diagonal terms (COO), the same plus a unit diagonal as CSC (``slots``: each
    unknown's diagonal entry in its ``data``; both None when ``smooth`` is 0: the terms would
    leave the sum) and each unknown's number of neighbours."""

    def compute():
        idx = np.full(inside.shape, -1, dtype=np.int64)
        n = int(inside.sum())
        idx[inside] = np.arange(n)
        pairs = []
        for a_, b_ in ((idx[:, :-1], idx[:, 1:]), (idx[:-1, :], idx[1:, :])):
            both = (a_ >= 0) & (b_ >= 0)
            pairs.append(np.stack([a_[both], b_[both]], axis=1))
        e = np.concatenate(pairs)
        deg = np.bincount(e.ravel(), minlength=n).astype(np.float64)
        lap = sparse.coo_matrix(
            (np.full(2 * len(e), -smooth), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
            shape=(n, n),
        )
        if smooth == 0:
            return idx, lap, None, None, deg
        # the sum's pattern and off-diagonal values do not depend on the diagonal's values
        # while none is zero (scipy drops zeros from a sum)
        A = (sparse.diags(np.ones(n)) + lap).tocsc()
        cols = np.repeat(np.arange(n), np.diff(A.indptr))
        slots = np.flatnonzero(A.indices == cols)  # column order: unknown order
        return idx, lap, A, slots, deg

    return shared("membrane", (inside, smooth), compute)


def _factorised(A: sparse.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """``b -> A^-1 b`` by :func:`splu`, bit for bit; in a sharing scope the fill-reducing
    column order (COLAMD's, which depends on the pattern alone) is found once per pattern and
    handed to the later matrices of that pattern, whose factorisation is then the same
    arithmetic on the same permuted matrix, about 15% faster."""
    fresh = {}

    def order():
        fresh["lu"] = splu(A)
        return np.argsort(fresh["lu"].perm_c)

    q = shared("fill_order", (A.shape, A.indptr, A.indices), order)
    if "lu" in fresh:  # this pattern's first (or no sharing scope)
        return fresh["lu"].solve
    lu = splu(A[:, q], permc_spec="NATURAL")
    if not np.array_equal(lu.perm_c, np.arange(len(q))):  # reordered again: not the same
        return splu(A).solve

    def solve(b):
        x = np.empty(len(q))
        x[q] = lu.solve(b)
        return x

    return solve


def _fusion_coarse(weight, inside, smooth, prior, anchors, anchor_weight, k):
    """:func:`fusion` on a grid ``k`` times coarser, interpolated back (see :func:`fuse`'s
    ``coarsen``)."""
    rows, cols = inside.shape
    rc, cc = -(-rows // k), -(-cols // k)
    pad = ((0, rc * k - rows), (0, cc * k - cols))
    w = np.pad(np.where(inside, weight, 0.0), pad)
    w_c = w.reshape(rc, k, cc, k).sum(axis=(1, 3))
    padded, inside_c = np.pad(inside, pad), np.zeros((rc, cc), dtype=bool)
    for i in range(k):  # any of the cell's k x k points (numpy's any over two short axes is slow)
        for j in range(k):
            inside_c |= padded[i::k, j::k]
    a = None if anchors is None else np.asarray(anchors, dtype=np.int64) // k
    solve = fusion(w_c, inside_c, smooth, prior * k * k, a, anchor_weight)

    def apply(measured: np.ndarray) -> np.ndarray:
        m = np.pad(measured, (*pad, (0, 0)))
        with np.errstate(invalid="ignore", divide="ignore"):
            m_c = (w[..., None] * m).reshape(rc, k, cc, k, 2).sum(axis=(1, 3)) / w_c[..., None]
        f_c = solve(np.nan_to_num(m_c))
        f = cv2.resize(f_c.astype(np.float32), (cc * k, rc * k), interpolation=cv2.INTER_LINEAR)
        return np.where(inside[..., None], f[:rows, :cols].astype(np.float64), 0.0)

    return apply
