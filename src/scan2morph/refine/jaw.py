"""The jaw prior: the skin of the chin moves with the mandible, rigidly.

Image correlation measures the chin's motion poorly once the jaw opens: the chin turns by
10-15 degrees, its shading and foreshortening change, and the pulled-back images differ by
several pixels that vary across it (synthetic ``car``: the flow leaves the chin 2-9 px from where
its skin went, and it moves a good start away by 1-2 px). The chin's *geometry* measures it: its
bony shape (the mentolabial sulcus over the chin's bulge) pins a rigid motion. So the neutral's
chin is registered to the take's surface by point-to-plane ICP
(:func:`scan2morph.align.region_motion`, started from the fit's correspondence), and each chin
vertex goes where that rigid motion carries its skin point, found in the take's range image
(:func:`scan2morph.template.sample.range_pixels`).

The prior holds only where the chin did move rigidly. It is used in full when the
registration's robust point-to-plane RMS (from the 80th percentile of the squares: a depth
camera's noisy edge of the chin does not count against it, a pout does) is within
``max_rmse_ratio`` times the residual the still skin (the alignment's region) leaves on the same
scans, the ICP converged and the chin's shape pins every direction of its motion (a chin that
the lips' rounding or a pout deforms is not rigid, a plane slides freely: both keep the flow's
answer), and the texture does not contradict it (where the flow measured most of the chin
confidently, it put it within a few px of where the rigid motion does:
:meth:`JawPrior.contradiction`; an expression that pulls the chin can fit a rigid turn of it within
the gate). Between ``max_rmse_ratio`` and ``fade_rmse_ratio`` times that residual its weight falls
linearly to 0 (:func:`gate_share`), so that a chin near the gate is not all in or all out: the
same take with a little more noise, or its landmarks clicked a little otherwise, got the whole
prior or none. Its weight rises from 0 to 1 along the way from the
lower lip's outer midpoint (iBUG 58) to the chin (iBUG 9), between the shares ``start`` and
``end`` of it: the lower lip and the sulcus under it move with the lips as much as with the jaw.
The refine stage moves a chin vertex towards the prior by its weight times one minus the flow's
confidence there: the prior fills in where the texture measured nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import binary_erosion

from scan2morph.align import (
    AlignResult,
    IcpParams,
    SampledSurface,
    invert,
    kabsch,
    region_motion,
    transform_points,
)
from scan2morph.align.noise import robust_rms
from scan2morph.errors import InputError, require_numbers
from scan2morph.geometry import finite_points, surface_normals
from scan2morph.refine.memo import shared
from scan2morph.scan.depth_cleanup import smooth_depth
from scan2morph.template.sample import range_pixels

__all__ = [
    "ChinMeshes",
    "JawParams",
    "JawPrior",
    "chin_weights",
    "gate_share",
    "jaw_prior",
    "scan_surface",
    "LOWER_LIP",
    "CHIN",
]

#: iBUG number of the lower lip's outer midpoint.
LOWER_LIP = 58
#: iBUG number of the chin's lowest point.
CHIN = 9
#: Fewest chin vertices valid in both meshes for a registration.
MIN_VERTICES = 12
#: The rigidity gate's least limit, mm: on noise-free scans the still skin leaves almost
#: nothing, but two samplings of curved skin differ by a few hundredths of a millimetre.
MIN_LIMIT_MM = 0.05
#: Smoothing of the take's range before its normals are taken, px; a jump in range beyond
#: NORMAL_JUMP_MM (mm) is another surface.
NORMAL_SIGMA_PX = 2.0
NORMAL_JUMP_MM = 3.0
#: Least :attr:`~scan2morph.align.AlignResult.constraint` of the chin's registration: the RMS
#: change of its fit (mm) per mm of the motion its shape pins least. The synthetic chins give
#: 0.07-0.09 (a slide known to about 0.1 mm); a plane gives 0.
MIN_CONSTRAINT = 0.02
#: The texture's veto (:meth:`JawPrior.contradiction`): when the flow measured at least
#: MIN_FLOW_SHARE of the registered chin's vertices with a confidence of FLOW_CONFIDENT or more
#: and puts them a median of more than MAX_FLOW_DISAGREEMENT_PX from where the rigid motion
#: puts them, the chin did not move rigidly. Measured on the default cohort (median, px): a
#: jaw opening leaves the flow confident on 12-46% of the chin (its foreshortened skin correlates
#: poorly), 0.7-3.0 px from the rigid motion; the other takes 0.2-1.7 px; a sad face pulling the
#: flat mesh scan's chin 4.2 px (63% confident; the prior cost it 0.52 against 0.42 of the
#: motion), the real head's smile on range scans 5.4 px (96%; 0.124 against 0.078).
FLOW_CONFIDENT = 0.5
MIN_FLOW_SHARE = 0.5
MAX_FLOW_DISAGREEMENT_PX = 3.5


@dataclass(frozen=True)
class JawParams:
    """Parameters of the jaw prior.

    Attributes
    ----------
    prior : bool
        Use the prior.
    start, end : float
        Shares of the way from iBUG 58 to iBUG 9 where the prior's weight starts to rise from 0
        and reaches 1; the vertices at weight 1 are the region registered.
    max_rmse_ratio : float
        The registration's RMSE gate, in units of the residual the still skin leaves: the prior
        in full up to it.
    fade_rmse_ratio : float
        Its weight falls linearly to 0 from ``max_rmse_ratio`` to this (same units; equal to it:
        a hard gate).
    """

    prior: bool = True
    start: float = 0.0
    end: float = 0.3
    max_rmse_ratio: float = 1.5
    fade_rmse_ratio: float = 2.5

    def __post_init__(self):
        if not isinstance(self.prior, bool | np.bool_):
            raise InputError("JawParams", f"prior: expected true or false, got {self.prior!r}")
        names = ("start", "end", "max_rmse_ratio", "fade_rmse_ratio")
        require_numbers("JawParams", {n: getattr(self, n) for n in names})
        if not 0.0 <= self.start < self.end <= 1.0:
            raise InputError(
                "JawParams",
                f"start, end: expected 0 <= start < end <= 1, got {self.start} and {self.end}",
            )
        if not self.max_rmse_ratio > 0:
            raise InputError(
                "JawParams", f"max_rmse_ratio: expected a positive ratio, got {self.max_rmse_ratio}"
            )
        if not self.fade_rmse_ratio >= self.max_rmse_ratio:
            raise InputError(
                "JawParams",
                f"fade_rmse_ratio: expected at least max_rmse_ratio ({self.max_rmse_ratio}), "
                f"got {self.fade_rmse_ratio}",
            )


@dataclass(frozen=True)
class JawPrior:
    """Where the jaw's rigid motion puts each chin vertex in a take.

    Attributes
    ----------
    points : (V, 2) float64
        Pixel positions in the take's image, px; NaN where there is no prior.
    weight : (V,) float64
        The prior's weight in [0, 1]; 0 everywhere when it is not used.
    motion : AlignResult
        The chin's registration (neutral frame onto the take's aligned surface).
    used : bool
    problem : str
        Why it is not used ("" when it is).
    share : float
        The gate's share of the prior in [0, 1] (:func:`gate_share`), already in ``weight``; 0
        when it is not used.
    """

    points: np.ndarray
    weight: np.ndarray
    motion: AlignResult | None
    used: bool
    problem: str
    share: float = 0.0

    def contradiction(self, points: np.ndarray, confidence: np.ndarray) -> str:
        """Why the flow contradicts the prior ("" when it does not, or the prior is not used):
        it measured most of the registered chin confidently, and elsewhere than the rigid motion
        puts it (:data:`MAX_FLOW_DISAGREEMENT_PX`): a chin that an expression pulls is not
        rigid, yet can fit a rigid turn of it within the rigidity gate.

        Parameters
        ----------
        points : (V, 2) float
            The flow's pixel positions in the take's image, px.
        confidence : (V,) float
            The flow's confidence in [0, 1].
        """
        if not self.used or self.share <= 0:
            return ""
        chin = (self.weight >= 0.5 * self.share) & np.isfinite(self.points).all(axis=1)
        p = np.asarray(points, dtype=np.float64)
        sure = chin & (np.asarray(confidence) >= FLOW_CONFIDENT) & np.isfinite(p).all(axis=1)
        if not chin.any() or sure.sum() < MIN_FLOW_SHARE * chin.sum():
            return ""
        apart = float(np.median(np.linalg.norm(self.points[sure] - p[sure], axis=1)))
        if apart <= MAX_FLOW_DISAGREEMENT_PX:
            return ""
        return (
            f"the texture contradicts it: the flow measured {int(sure.sum())} of the chin's "
            f"{int(chin.sum())} vertices confidently, a median {apart:.1f} px from where the "
            f"rigid motion puts them (at most {MAX_FLOW_DISAGREEMENT_PX:g}): the chin did not "
            "move rigidly"
        )

    @classmethod
    def unused(cls, n: int, problem: str, motion: AlignResult | None = None) -> JawPrior:
        """A prior that is not used, for ``n`` template vertices, and why (``motion``: the
        chin's registration, when there was one, kept for the record)."""
        return cls(np.full((n, 2), np.nan), np.zeros(n), motion, False, problem)

    def refused(self, problem: str) -> JawPrior:
        """This prior not used, for ``problem`` (its registration kept for the record)."""
        return JawPrior.unused(len(self.weight), problem, self.motion)

    def fill(self, points: np.ndarray, confidence: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The prior where the flow measured nothing: each point moves towards it by its weight
        times one minus the flow's ``confidence`` (a confident flow stays: a chin that is rigid
        but not quite, or a pose the ICP slid, must not override it).

        Parameters
        ----------
        points : (V, 2) float
            The flow's pixel positions in the take's image, px.
        confidence : (V,) float
            The flow's confidence in [0, 1].

        Returns
        -------
        points : (V, 2) float64
        confidence : (V,) float64
            That of either measurement: ``c + share``, ``share = weight (1 - c)``.
        """
        c = np.asarray(confidence, dtype=np.float64)
        share = np.where(np.isfinite(self.points).all(axis=1), self.weight * (1.0 - c), 0.0)
        return self.apply(points, share), c + share

    def apply(self, points: np.ndarray, share: np.ndarray | None = None) -> np.ndarray:
        """Pixel positions moved towards the prior.

        Parameters
        ----------
        points : (V, 2) float
            Pixel positions in the take's image, px.
        share : (V,) float, optional
            How far each moves, in [0, 1] (default the prior's weight); 0 where the prior has
            no point.

        Returns
        -------
        (V, 2) float64
        """
        w = self.weight if share is None else np.asarray(share, dtype=np.float64)
        w = np.where(np.isfinite(self.points).all(axis=1), w, 0.0)[:, None]
        return np.asarray(points, dtype=np.float64) + w * np.nan_to_num(self.points - points)


def chin_weights(
    vertices2d: np.ndarray, ibug_xy: np.ndarray, start: float, end: float
) -> np.ndarray:
    """(V,) weight of the jaw prior at each template vertex.

    Parameters
    ----------
    vertices2d : (V, 2) float
        Template vertices, template units.
    ibug_xy : (68, 2) float
        The template's iBUG points.
    start, end : float
        Shares of the way from iBUG 58 to iBUG 9 (projected on that axis) where the weight
        starts to rise from 0 and reaches 1.
    """
    ibug = np.asarray(ibug_xy, dtype=np.float64)
    v = np.asarray(vertices2d, dtype=np.float64)
    if ibug.shape != (68, 2) or v.ndim != 2 or v.shape[1] != 2:
        raise InputError(
            "template",
            f"vertices2d, ibug_xy: expected (V, 2) and (68, 2), got {v.shape} and {ibug.shape}",
        )
    if not 0.0 <= start < end:
        raise InputError("template", f"start, end: expected 0 <= start < end, got {start}, {end}")
    lip, chin = ibug[[LOWER_LIP - 1, CHIN - 1]]
    axis = chin - lip
    if not np.isfinite(axis).all() or float(axis @ axis) == 0.0:
        raise InputError("template", "ibug_xy: the lower lip (iBUG 58) and chin (iBUG 9) coincide")
    share = (v - lip) @ axis / float(axis @ axis)
    return np.clip((share - start) / (end - start), 0.0, 1.0)


@dataclass(frozen=True)
class ChinMeshes:
    """The per-vertex inputs of :func:`jaw_prior` (checked there).

    Attributes
    ----------
    neutral : (V, 3) float, mm
        The neutral's mesh (neutral frame); NaN where invalid.
    neutral_valid : (V,) bool
    take : (V, 3) float, mm
        The take's aligned fit (neutral frame); NaN where invalid. Its correspondence starts
        the registration.
    take_valid : (V,) bool
    weights : (V,) float
        :func:`chin_weights`; the vertices at 1 are registered.
    still : (V,) bool
        Skin that the alignment holds still (its ICP region): the rigidity gate's reference.
    """

    neutral: np.ndarray
    neutral_valid: np.ndarray
    take: np.ndarray
    take_valid: np.ndarray
    weights: np.ndarray
    still: np.ndarray


def jaw_prior(
    meshes: ChinMeshes,
    take_xyz: np.ndarray,
    take_transform: np.ndarray,
    icp: IcpParams | None = None,
    max_rmse_ratio: float = 1.5,
    source: str = "subject/take",
    fade_rmse_ratio: float | None = None,
) -> JawPrior:
    """The jaw prior of one take.

    Parameters
    ----------
    meshes : ChinMeshes
        The neutral's and the take's meshes, the chin's weights and the still skin.
    take_xyz : (H, W, 3) float, mm
        The take's range image (its own frame): the surface registered to, and where the moved
        skin points are looked up.
    take_transform : (4, 4) float
        The take's alignment (its frame -> the neutral frame).
    icp : IcpParams, optional
        ICP settings (the alignment's).
    max_rmse_ratio : float
        The rigidity gate: the chin's point-to-plane RMSE at most this many times the still
        skin's (robust) residual against the take's surface under the alignment, the RMSE that
        a rigid motion leaves on these scans, for the prior in full.
    source : str
        ``subject/take``, for messages.
    fade_rmse_ratio : float, optional
        Beyond ``max_rmse_ratio`` the prior's weight falls linearly to 0 at this many times the
        still skin's residual (:func:`gate_share`); default ``max_rmse_ratio``: a hard gate.

    Returns
    -------
    JawPrior
    """
    fade = max_rmse_ratio if fade_rmse_ratio is None else fade_rmse_ratio
    if not fade >= max_rmse_ratio > 0:
        raise InputError(
            source,
            f"jaw prior: expected 0 < max_rmse_ratio <= fade_rmse_ratio, got {max_rmse_ratio} "
            f"and {fade}",
        )
    m = meshes
    weights, neutral, neutral_valid, take, take_valid, still = _checked(
        m.weights, m.neutral, m.neutral_valid, m.take, m.take_valid, m.still, source
    )
    xyz = _checked_scan(take_xyz, take_transform, source)
    n = len(weights)

    def refused(problem, motion=None):
        return JawPrior.unused(n, problem, motion)

    core = (weights >= 1.0) & neutral_valid
    both = core & take_valid
    if both.sum() < MIN_VERTICES:
        return refused(
            f"only {int(both.sum())} chin vertices valid in both meshes "
            f"(at least {MIN_VERTICES} needed)"
        )
    still = still & neutral_valid  # not in place: the caller's array stays as it was
    if still.sum() < MIN_VERTICES:
        return refused(f"only {int(still.sum())} still skin vertices (align.icp_region) valid")
    start = kabsch(neutral[both], take[both], source=source)  # the fit's correspondence
    near = (weights > 0) & neutral_valid
    mapped = transform_points(take_transform, xyz)  # the whole image once, for both windows
    margin = _margin(icp)
    surface, offset, window = _scan_surface(
        xyz, mapped, take_transform, transform_points(start, neutral[near]), margin, source
    )
    if surface is None:
        return refused("the take's scan does not show the chin")
    reference = _still_residual(xyz, mapped, take_transform, neutral[still], margin, source)
    if reference is None:
        return refused("the take's scan does not show the still skin (align.icp_region)")
    full = max(max_rmse_ratio * reference, MIN_LIMIT_MM)
    limit = full * fade / max_rmse_ratio
    motion = region_motion(
        neutral[core], start, surface, replace(icp or IcpParams(), max_rmse_mm=limit), source
    )
    name = "max_rmse_ratio" if fade == max_rmse_ratio else "fade_rmse_ratio"
    gate = (name, fade, MIN_LIMIT_MM * fade / max_rmse_ratio)
    problem = _motion_problem(motion, limit, reference, gate)
    if problem:
        return refused(problem, motion)
    share = gate_share(motion.residual_rmse, full, limit)
    moved = transform_points(motion.transform, neutral[near])
    points = np.full((n, 2), np.nan)
    points[near] = offset + range_pixels(
        window, transform_points(invert(take_transform), moved), source=source
    )
    found = np.isfinite(points).all(axis=1)
    return JawPrior(points, np.where(found, share * weights, 0.0), motion, True, "", share)


def gate_share(residual: float, full: float, limit: float) -> float:
    """The share of the jaw prior a chin's registration earns: 1 for a residual up to
    ``full``, falling linearly to 0 at ``limit`` (mm all three; ``limit == full``: a step)."""
    if residual <= full:
        return 1.0
    if residual >= limit:
        return 0.0
    return float((limit - residual) / (limit - full))


def _still_residual(xyz, mapped, take_transform, still_points, margin, source) -> float | None:
    """What a rigid motion leaves on these scans: the robust RMS point-to-plane residual, mm,
    of the still skin's points (n, 3) (neutral frame) against the take's scan ``xyz`` (its
    frame; ``mapped`` into the neutral frame by ``take_transform``) under the alignment, over
    the points its data covers (as the chin's are); robust, since a smile's temples move. None
    when the scan shows fewer than :data:`MIN_VERTICES` of them."""
    still_surface = _scan_surface(xyz, mapped, take_transform, still_points, margin, source)[0]
    plane = np.zeros(0)
    if still_surface is not None:
        plane, seen, _ = still_surface.residuals(
            still_points, still_surface.reach(still_points, 0.0)
        )
        plane = plane[seen]
    return robust_rms(plane) if plane.size >= MIN_VERTICES else None


def _motion_problem(motion, limit: float, reference: float, gate: tuple) -> str:
    """Why the chin's registered ``motion`` is not used ("" when it is): its shape does not pin
    it (:data:`MIN_CONSTRAINT`), or it failed its gate (its RMSE above ``limit``, mm: the still
    skin's ``reference`` residual times the ratio of ``gate``, ``(name, ratio, floor)``: the
    setting's name, its value and the least limit, mm)."""
    if not motion.constraint >= MIN_CONSTRAINT:
        return (
            f"the chin's shape does not pin its motion: a slide of 1 mm changes its fit by "
            f"{motion.constraint:.3f} mm RMS (at least {MIN_CONSTRAINT:g} needed)"
        )
    if motion.ok:
        return ""
    if motion.converged and motion.residual_rmse > limit:
        name, ratio, floor = gate
        return (
            f"the chin did not move rigidly: robust point-to-plane RMS {motion.residual_rmse:.3f} "
            f"mm > {limit:.3f} mm ({name} {ratio:g} x the {reference:.3f} mm the still skin "
            f"leaves, at least {floor:.3g} mm)"
        )
    return "; ".join(motion.problems)


def _checked(weights, neutral, neutral_valid, take, take_valid, still, source):
    """The per-vertex inputs of :func:`jaw_prior` as arrays, or a clear error."""
    weights = np.asarray(weights, dtype=np.float64)
    n = len(weights)
    if weights.ndim != 1 or not np.isfinite(weights).all():
        raise InputError(source, f"weights: expected (V,) finite chin weights, got {weights.shape}")
    out = [weights]
    for name, value, width in (
        ("neutral", neutral, 3),
        ("neutral_valid", neutral_valid, 0),
        ("take", take, 3),
        ("take_valid", take_valid, 0),
        ("still", still, 0),
    ):
        a = np.asarray(value, dtype=np.float64 if width else bool)
        want = (n, width) if width else (n,)
        if a.shape != want:
            raise InputError(source, f"{name}: expected shape {want}, got {a.shape}")
        out.append(a)
    return out


def _checked_scan(xyz, transform, source):
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or min(xyz.shape[:2]) < 2:
        raise InputError(source, f"take_xyz: expected an (H, W, 3) range image, got {xyz.shape}")
    t = np.asarray(transform, dtype=np.float64)
    if t.shape != (4, 4) or not np.isfinite(t).all():
        raise InputError(
            source, f"take_transform: expected a finite (4, 4) transform, got {t.shape}"
        )
    return xyz


def scan_surface(
    xyz: np.ndarray,
    transform: np.ndarray,
    placed: np.ndarray,
    icp: IcpParams | None = None,
    source: str = "range image",
) -> tuple[SampledSurface | None, np.ndarray | None, np.ndarray | None]:
    """A range image's surface where some points can be.

    The window holds the pixels within the ICP's correspondence distance of the points' box;
    their normals are those of the range smoothed over :data:`NORMAL_SIGMA_PX` (a pixel's own
    normal is tilted by its noise: 0.1 mm over 0.7 mm of spacing is 8 degrees, enough to pin a
    plane). The data's edge: pixels next to one without data (the image's border counts as
    none; a depth step with data on both sides does not, and its far side's residuals are
    large, which the robust kernel weighs down).

    Parameters
    ----------
    xyz : (H, W, 3) float, mm
        The range image, NaN where there is no data.
    transform : (4, 4) float
        The image's frame -> the frame of ``placed`` and of the surface returned.
    placed : (n, 3) float, mm
        Where the points to register are (finite).
    icp : IcpParams, optional
        Its ``max_correspondence_mm`` is the window's margin.
    source : str
        Label for error messages.

    Returns
    -------
    surface : SampledSurface or None
        None when the window holds no more than :data:`MIN_VERTICES` pixels with data.
    offset : (2,) float64 or None
        The window's (column, row) in the image, px.
    window : (h, w, 3) float64 or None
        The window of ``xyz``.
    """
    xyz = _checked_scan(xyz, transform, source)
    placed = np.asarray(placed, dtype=np.float64)
    if placed.ndim != 2 or placed.shape[1] != 3 or not len(placed) or not np.isfinite(placed).all():
        raise InputError(source, f"placed: expected finite (n, 3) points, got {placed.shape}")
    mapped = transform_points(transform, xyz)
    return _scan_surface(xyz, mapped, transform, placed, _margin(icp), source)


def _margin(icp: IcpParams | None) -> float:
    """The windows' margin around the points, mm: the ICP's correspondence distance."""
    return float((icp or IcpParams()).max_correspondence_mm)


def _scan_surface(xyz, mapped, transform, placed, reach, source):
    """:func:`scan_surface` on checked inputs, with the image already mapped by ``transform``."""
    lo, hi = placed.min(axis=0) - reach, placed.max(axis=0) + reach
    inside = np.ones(mapped.shape[:2], dtype=bool)
    with np.errstate(invalid="ignore"):  # each coordinate on its own: a 3-long .all is slow
        for k in range(3):
            inside &= (mapped[..., k] >= lo[k]) & (mapped[..., k] <= hi[k])
    rows, cols = np.nonzero(inside)
    if not len(rows):
        return None, None, None
    pad = int(np.ceil(3 * NORMAL_SIGMA_PX)) + 1
    r0, c0 = max(rows.min() - pad, 0), max(cols.min() - pad, 0)
    window = xyz[r0 : rows.max() + pad + 1, c0 : cols.max() + pad + 1]
    normals = shared(  # a window the draws of a click-noise error bar share, once
        "window_normals",
        (window,),
        lambda: surface_normals(smooth_depth(window, NORMAL_SIGMA_PX, NORMAL_JUMP_MM)),
    )
    have = finite_points(window) & finite_points(normals)
    if have.sum() <= MIN_VERTICES:
        return None, None, None
    # the image's own border is the edge of its data; a window's cut is not
    rows_, cols_ = have.shape
    padded = np.pad(have, 1, constant_values=False)
    data = finite_points(xyz)
    r1, c1 = r0 + rows_, c0 + cols_
    if r0 > 0:
        padded[0, 1:-1] = data[r0 - 1, c0:c1]
    if r1 < xyz.shape[0]:
        padded[-1, 1:-1] = data[r1, c0:c1]
    if c0 > 0:
        padded[1:-1, 0] = data[r0:r1, c0 - 1]
    if c1 < xyz.shape[1]:
        padded[1:-1, -1] = data[r0:r1, c1]
    edge = have & ~binary_erosion(padded, np.ones((3, 3), dtype=bool))[1:-1, 1:-1]
    rotation = np.asarray(transform, dtype=np.float64)[:3, :3]
    surface = SampledSurface(
        transform_points(transform, window[have]), normals[have] @ rotation.T, source, edge[have]
    )
    return surface, np.array([c0, r0], dtype=np.float64), window
