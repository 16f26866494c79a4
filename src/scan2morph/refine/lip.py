"""The lip priors: the upper lip keeps its length from the vermilion border to the slit, the
lower lip its share of it.

Image correlation measures the lips poorly when the mouth rounds or opens: the upper lip rolls
and foreshortens, its inner part turns away from the camera, and the flow leaves the slit's
vertices 3.5-8 px from where their skin went (synthetic ``she``, ``too``, ``eel``, ``man``). Its
material hardly stretches, though: on the synthetic visemes the 3D length from the vermilion
border to the slit changes by a median of 1-7%. And the border is visible in any light: the
lips are redder than the skin around them, and redness ``R / (R + G + B)`` does not change with
the light's brightness.

Each vertex of the upper lip (:func:`scan2morph.template.regions.lip`: the slit, the lip's
body, the border) lies on a *profile*: the image line of its column, from the column's slit
vertex through its border vertex and on past the border, moved sideways through the vertex.
Along it, in each image:

1. the border is the steepest fall of redness going outward (:func:`~scan2morph.refine.lip_profile.vermilion_edge`), and the
   vertex's skin point lies at a signed length from it along the neutral's surface (mm);
2. the take's border is then registered to the neutral's: the redness around it, as a function
   of the length along the surface, is matched (the shift of best correlation), so that a
   border whose fall is broad or uneven (real lips under stubble) is found at the same skin;
3. in the take the vertex goes to its length from the border, along the take's surface. A flow
   within ``stretch`` of the lip's length of it stays (the lip may stretch that much); one
   beyond goes to the nearest length allowed.

The vertices so placed are held; the lip's others follow harmonically
(:func:`scan2morph.geometry.harmonic_fill`), and everything else keeps the flow's answer.
(Letting the skin next to the border follow too doubled car's click-noise error bar, 0.035 ->
0.065: it flips whether the nasolabial skin next to car's torn patch tears, from one draw of the
clicks to the next; accuracy the same.)

The prior needs lips that are redder than the skin, in both images: a grey image, a sprayed
stereo neutral or a painted face shows no border, and the prior is then not used (its
``problem`` says why). A vertex whose border is not found or not matched, whose length the
take's surface cannot carry, or whose correction would exceed ``max_shift`` of the lip's height
is not placed; with fewer than ``min_share`` of the lip's vertices placed the prior is not used.

The lower lip shortens by 16-22% as it rounds (she, too), so a length prior moves its slit
vertices further from their skin points. With ``shrink`` (the refine stage's lower lip) the lip
may shorten instead: where the take's surface ends towards an open mouth is taken as its slit,
and each vertex keeps its share of the lip's length from the border. A closed mouth, whose
surface resumes past a crease narrower than :data:`CREASE_PX`, keeps the flow's answer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError, require_numbers
from scan2morph.geometry import harmonic_fill
from scan2morph.refine.lip_profile import (
    LipImage,
    arc_length,
    lip_profile,
    redness,
    register_redness,
    vermilion_edge,
)
from scan2morph.refine.memo import shared
from scan2morph.scan.view import scanner_view
from scan2morph.template.regions import Lip

__all__ = ["LipImages", "LipParams", "LipPrior", "redness", "vermilion_edge", "lip_prior"]

#: The harmonic fill's pull of the lip's followers towards 0 (:func:`harmonic_fill`'s ``ridge``):
#: a follower's weight stays below a placed vertex's 1.
_FILL_RIDGE = 1e-12
#: A profile runs past its border vertex by this share of the lip's height (the skin beyond
#: the border); the take's runs ``max_shift`` further at both ends (the vertex may go there).
BEYOND = 0.6
#: The neutral's profile starts this share of the lip's height before its vertex (or its
#: slit's row), so that the vertex is not at its end (where the smoothing is one-sided).
PAST = 0.25
#: Least height of a lip in an image (its column's slit to border), px: the border cannot be
#: found on less.
MIN_HEIGHT_PX = 2.0
#: Largest ``max_shift`` (shares of the lip's height).
MAX_SHIFT = 2.0
#: A gap in the take's surface narrower than this, px, with surface beyond it, is a closed
#: mouth's crease, not the lip's end (``shrink``).
CREASE_PX = 8.0
#: The registration's precision, mm: a vertex's length from the border is held to within this
#: (plus ``stretch`` of itself).
FLOOR_MM = 0.1
#: The share of the lip (from the border) whose redness is registered.
NEAR = 0.5


@dataclass(frozen=True)
class LipParams:
    """Parameters of a lip's prior.

    Attributes
    ----------
    prior : bool
        Use the prior.
    min_contrast : float
        Least redness step at the border, lip minus skin (each side's mean along the profile),
        in both images.
    search : float
        The border is looked for within this share of the lip's height of the border vertex,
        and the take's is matched to the neutral's within this share of the lip's length.
    max_shift : float
        Largest correction of a lip vertex, in shares of the lip's height in the take (at most
        :data:`MAX_SHIFT`).
    min_share : float
        Least share of the lip's vertices placed for the prior to be used.
    stretch : float
        The strain the lip may take: a vertex's length from the border may change by this share
        of itself (plus :data:`FLOOR_MM`, the registration's precision) before the prior moves
        it; a flow within that is kept, one beyond goes to the nearest length allowed.
    shrink : float
        0 for a lip that keeps its length (the upper lip). Above 0, the lip may shorten by up
        to this share (the lower lip, which rounds): where the take's surface ends towards an
        open mouth is taken as the slit, and the lip's vertices keep their share of its length
        (a closed mouth keeps the flow's answer).
    """

    prior: bool = True
    min_contrast: float = 0.02
    search: float = 0.5
    max_shift: float = 0.6
    min_share: float = 0.5
    stretch: float = 0.1
    shrink: float = 0.0

    def __post_init__(self):
        if not isinstance(self.prior, bool | np.bool_):
            raise InputError("LipParams", f"prior: expected true or false, got {self.prior!r}")
        names = ("min_contrast", "search", "max_shift", "min_share", "stretch", "shrink")
        require_numbers("LipParams", {n: getattr(self, n) for n in names})
        for name, ok, expected in (
            ("min_contrast", 0.0 < self.min_contrast < 1.0, "0 < contrast < 1"),
            ("search", 0.0 < self.search < 1.0, "0 < share < 1"),
            ("max_shift", 0.0 < self.max_shift <= MAX_SHIFT, f"0 < share <= {MAX_SHIFT}"),
            ("stretch", 0.0 <= self.stretch < 1.0, "0 <= share < 1"),
            ("shrink", 0.0 <= self.shrink < 1.0, "0 <= share < 1"),
            ("min_share", 0.0 < self.min_share <= 1.0, "0 < share <= 1"),
        ):
            if not ok:
                raise InputError(
                    "LipParams", f"{name}: expected {expected}, got {getattr(self, name)}"
                )


@dataclass(frozen=True)
class LipPrior:
    """Where the upper lip's length puts its vertices in a take.

    Attributes
    ----------
    points : (V, 2) float64
        Pixel positions in the take's image, px, on the lip
        (:class:`~scan2morph.template.regions.Lip`); NaN elsewhere, or when not used.
    weight : (V,) float64
        1 at the lip's vertices placed by their profiles, 0 off the lip, and at the lip's others
        the harmonic interpolation of the two (the share of a vertex's correction that
        its placed neighbours decide), in [0, 1].
    measured : int
        The lip's vertices placed by their profiles.
    vertices : int
        The lip's vertices.
    contrast : float
        The median redness step at the border over the placed vertices (both images' lesser).
    used : bool
    problem : str
        Why it is not used ("" when it is).
    """

    points: np.ndarray
    weight: np.ndarray
    measured: int
    vertices: int
    contrast: float
    used: bool
    problem: str

    @classmethod
    def unused(cls, n: int, problem: str, measured: int = 0, vertices: int = 0, contrast=0.0):
        """A prior that is not used, for ``n`` template vertices, and why."""
        return cls(
            np.full((n, 2), np.nan), np.zeros(n), measured, vertices, contrast, False, problem
        )

    def apply(self, points: np.ndarray, confidence: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The lip's vertices placed by the prior.

        The flow's own answer on the lip is not kept, however confident: it slides where the lip
        rolls (its texture there correlates with the wrong skin).

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
            ``c + weight (1 - c)`` on the lip.
        """
        p = np.asarray(points, dtype=np.float64)
        c = np.asarray(confidence, dtype=np.float64)
        has = np.isfinite(self.points).all(axis=1)
        w = np.where(has, self.weight, 0.0)
        return np.where(has[:, None], self.points, p), c + w * (1.0 - c)


@dataclass(frozen=True)
class LipImages:
    """The neutral's and the take's images of :func:`lip_prior` (checked there), and how their
    range images are sampled.

    Attributes
    ----------
    neutral_color, take_color : (H, W, 3)
        Colour images, pixel to pixel with the range images.
    neutral_xyz, take_xyz : (H, W, 3) float
        Range images, mm (any frame: only lengths are used), NaN where there is no data.
    min_weight, max_slope_deg : float
        The range images' sampling rules (:func:`~scan2morph.template.sample.sample_range`).
    """

    neutral_color: np.ndarray
    neutral_xyz: np.ndarray
    take_color: np.ndarray
    take_xyz: np.ndarray
    min_weight: float = 0.5
    max_slope_deg: float | None = 80.0


def lip_prior(
    lip: Lip,
    vertices2d: np.ndarray,
    neutral_points: np.ndarray,
    take_points: np.ndarray,
    images: LipImages,
    faces: np.ndarray,
    params: LipParams,
    source: str = "take",
) -> LipPrior:
    """Where the upper lip's length from the vermilion border puts its vertices in a take.

    Parameters
    ----------
    lip : Lip
        The template's upper lip (:func:`scan2morph.template.regions.lip`).
    vertices2d : (V, 2) float
        The template's vertices, template units (the lip's columns).
    neutral_points, take_points : (V, 2) float
        The template's vertices in the neutral's image (its fit: they define the skin points)
        and in the take's (the flow's answer), px.
    images : LipImages
        The neutral's and the take's colour and range images.
    faces : (F, 3) int
        The template's triangles (the harmonic interpolation's mesh).
    params : LipParams
    source : str
        ``subject/take``, for messages.

    Returns
    -------
    LipPrior

    Raises
    ------
    InputError
        The points or template vertices are not (V, 2) of one count, the lip's or the faces'
        indices are not among them, the lip has no slit or border vertex, or an image has the
        wrong shape.
    """
    pn = _points(neutral_points, "neutral_points", source)
    pt = _points(take_points, "take_points", source)
    v2 = _points(vertices2d, "vertices2d", source)
    f = _check_mesh(lip, (pn, pt, v2), faces, source)
    i, rules = images, (images.min_weight, images.max_slope_deg)
    img_n, img_t = (
        _lip_image(color, xyz, what, rules, source)
        for what, color, xyz in (("neutral", i.neutral_color, i.neutral_xyz), ("take", i.take_color, i.take_xyz))
    )  # fmt: skip
    targets, contrasts, reasons = _place_all(lip, v2, (pn, pt), (img_n, img_t), params)
    ok = np.isfinite(targets).all(axis=1)
    measured, total, n = int(ok.sum()), len(lip.vertices), len(pn)
    contrast = float(np.median(contrasts)) if contrasts else 0.0
    if measured == 0 or measured < params.min_share * total:
        why = "; ".join(f"{m}: {reasons[m]}" for m in sorted(reasons, key=reasons.get)[::-1])
        problem = (
            f"only {measured} of the lip's {total} vertices placed (at least "
            f"{100 * params.min_share:.0f}% needed); not placed: {why}"
        )
        return LipPrior.unused(n, problem, measured, total, contrast)
    points, weight = _held(lip.vertices, targets, pt, f)
    return LipPrior(points, weight, measured, total, contrast, True, "")


def _check_mesh(lip: Lip, points: tuple, faces, source: str) -> np.ndarray:
    """``faces`` as an (F, 3) array, checked with the lip against the vertex count of
    ``points`` (the neutral's, the take's and the template's (V, 2) vertices, one count)."""
    pn, pt, v2 = points
    n = len(pn)
    if len(pt) != n or len(v2) != n:
        raise InputError(
            source,
            f"lip prior: {n} neutral points, {len(pt)} take points and {len(v2)} template "
            f"vertices (expected one count)",
        )
    _check_lip(lip, n, source)
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= n)):
        raise InputError(source, f"lip prior: faces {f.shape}: expected (F, 3) indices below {n}")
    return f


def _lip_image(color, xyz, what: str, rules: tuple, source: str) -> LipImage:
    """The neutral's or the take's (``what``) image: the redness of ``color``, the range image
    ``xyz`` (checked pixel to pixel with it), its scanner's view for the depth-step rule (when
    ``rules`` = ``(min_weight, max_slope_deg)`` has one)."""
    # float32, what the profiles sample (:func:`~scan2morph.refine.template_space.pull_back`)
    red = shared("redness", (np.asarray(color),), lambda: redness(color, source).astype(np.float32))
    shape = np.shape(xyz)
    if len(shape) != 3 or shape[2] != 3 or shape[:2] != red.shape:
        raise InputError(
            source,
            f"lip prior: the {what}'s range image has shape {shape}, expected "
            f"{(*red.shape, 3)} (pixel to pixel with its colour image)",
        )
    xyz = np.asarray(xyz, dtype=np.float64)
    min_weight, max_slope_deg = rules
    view = None if max_slope_deg is None else scanner_view(xyz)
    return LipImage(red, xyz, view, min_weight, max_slope_deg, source)


def _place_all(lip: Lip, v2, points: tuple, images: tuple, params: LipParams) -> tuple:
    """Each lip vertex placed in the take (:func:`_place`): ``(targets, contrasts, reasons)``,
    its place (n, 2) px (NaN: not placed), the redness steps of those placed, and how many were
    not placed for each reason. ``points`` are the template's vertices in the neutral's and the
    take's image (V, 2) px, ``images`` the two :class:`LipImage`."""
    (pn, pt), (img_n, img_t) = points, images
    columns = lip.columns(v2)
    border_n, border_t = lip.border_points(v2, pn), lip.border_points(v2, pt)
    lines = [
        _Line(pn[lip.inner[c]], border_n[c], pn[v])
        for v, c in zip(lip.vertices, columns, strict=True)
    ]
    # the neutral's profiles depend on the neutral alone: once for every take of a draw
    parts = (lip.vertices, lip.inner, columns, pn, img_n.red, img_n.xyz, img_n.min_weight)
    profiles = shared(
        "lip_profiles",
        (*parts, img_n.max_slope_deg, params.search, params.min_contrast),
        lambda: [_neutral_profile(line, img_n, params) for line in lines],
    )
    targets = np.full((len(lip.vertices), 2), np.nan)
    contrasts = []
    reasons: dict[str, int] = {}
    for k, (v, c) in enumerate(zip(lip.vertices, columns, strict=True)):
        i = lip.inner[c]
        take = _Line(pt[i], border_t[c], pt[v])
        found = _place(lines[k], take, profiles[k], img_t, params)
        if isinstance(found, str):
            reasons[found] = reasons.get(found, 0) + 1
        else:
            targets[k], contrast = found
            contrasts.append(contrast)
    return targets, contrasts, reasons


def _held(vertices, targets, pt, faces) -> tuple[np.ndarray, np.ndarray]:
    """The prior's ``(points (V, 2) px, weight (V,))``: the lip's placed vertices held at their
    ``targets`` with weight 1, its others following harmonically (moved and weighted by the
    harmonic fill of the placed ones' corrections from the take's points ``pt``), NaN and 0
    elsewhere (everything else keeps the flow's answer)."""
    n = len(pt)
    ok = np.isfinite(targets).all(axis=1)
    fixed = np.ones(n, dtype=bool)
    fixed[vertices[~ok]] = False
    values = np.zeros((n, 3))
    values[vertices[ok], :2] = targets[ok] - pt[vertices[ok]]
    values[vertices[ok], 2] = 1.0
    filled = harmonic_fill(values, faces, fixed, unreachable=0.0, ridge=_FILL_RIDGE)
    points = np.full((n, 2), np.nan)
    points[vertices] = pt[vertices] + filled[vertices, :2]
    weight = np.zeros(n)
    weight[vertices] = np.clip(filled[vertices, 2], 0.0, 1.0)
    return points, weight


#: Why a lip vertex was not placed (the prior's ``problem`` counts them).
NO_BORDER = "no vermilion border (a redness step) within lip_search in both images"
NOT_MATCHED = "the take's border did not match the neutral's"
NO_SURFACE = "the take's surface does not carry the vertex's length from the border"
TOO_FAR = "the correction exceeds lip_max_shift"
NO_LINE = f"no profile (a point missing, or the lip under {MIN_HEIGHT_PX:g} px high)"


def _points(points, name, source):
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(source, f"lip prior: {name} has shape {p.shape}, expected (V, 2)")
    return p


def _check_lip(lip: Lip, n: int, source: str) -> None:
    """An InputError unless the lip has slit and border vertices, all among ``n``."""
    parts = {k: np.asarray(getattr(lip, k)) for k in ("inner", "outline", "between")}
    for name, idx in parts.items():
        if idx.ndim != 1 or (idx.size and (idx.min() < 0 or idx.max() >= n)):
            raise InputError(
                source, f"lip prior: the lip's {name} {idx.shape}: expected indices below {n}"
            )
    if not len(parts["inner"]) or not len(parts["outline"]):
        raise InputError(source, "lip prior: the lip has no slit or no border vertex")


@dataclass(frozen=True)
class _Line:
    """A vertex's profile in one image: the line of its column (slit vertex ``inner`` to the
    border's point ``border`` above it, px) moved sideways through the vertex ``at``; ``t`` is
    0 on the slit's row and 1 on the border's."""

    inner: np.ndarray
    border: np.ndarray
    at: np.ndarray

    @property
    def direction(self) -> np.ndarray:
        return self.border - self.inner

    @property
    def t(self) -> float:
        """The vertex's own position along the line."""
        d = self.direction
        return float((self.at - self.inner) @ d / (d @ d))

    @property
    def origin(self) -> np.ndarray:
        """The line's point at t = 0."""
        return self.at - self.t * self.direction

    def ok(self) -> bool:
        finite = np.isfinite([*self.inner, *self.border, *self.at]).all()
        return bool(finite and np.linalg.norm(self.direction) >= MIN_HEIGHT_PX)


def _neutral_profile(neutral: _Line, img_n: LipImage, params: LipParams):
    """A lip vertex's profile in the neutral (:func:`_place`'s first half): ``(t, redness,
    arc length from the border, the vertex's length, the lip's length, the border's redness
    step)``, or why the vertex is not placed (:data:`NO_LINE`, :data:`NO_BORDER`,
    :data:`NO_SURFACE`)."""
    if not neutral.ok():
        return NO_LINE
    end = 1.0 + BEYOND
    t, r, xyz, _ = lip_profile(
        img_n, neutral.origin, neutral.direction, min(neutral.t, 0.0) - PAST, end
    )
    edge = vermilion_edge(r, t, 1.0, params.search, end)
    if edge is None or edge[1] < params.min_contrast:
        return NO_BORDER
    arc_n = arc_length(t, xyz, edge[0])
    length = np.interp(neutral.t, t, arc_n)  # the vertex's, from the border (< 0 on the lip)
    lip_length = -np.interp(0.0, t, arc_n)
    if not (np.isfinite(length) and np.isfinite(lip_length) and lip_length > 0.0):
        return NO_SURFACE
    return t, r, arc_n, length, lip_length, edge[1]


def _place(neutral: _Line, take: _Line, profile, img_t: LipImage, params: LipParams):
    """One lip vertex: its place in the take (2,) px and the border's redness step (the lesser
    of the two images'), or why not (one of the reasons above). ``profile`` is the vertex's
    :func:`_neutral_profile`.

    The vertex's skin point lies at a signed length from the vermilion border along the
    neutral's surface. The border is found in each image (:func:`~scan2morph.refine.lip_profile.vermilion_edge`), and the
    take's is then registered to the neutral's: the redness around it, as a function of the
    length along the surface, is matched (the shift of best correlation), so that a border
    whose fall is broad or uneven is found at the same skin in both. In the take the vertex
    goes to its length from the border; a flow within ``stretch`` of that length (plus
    :data:`FLOOR_MM`) stays, one beyond goes to the nearest length allowed."""
    if not (neutral.ok() and take.ok()):
        return NO_LINE
    if isinstance(profile, str):
        return profile
    t, r, arc_n, length, lip_length, contrast = profile
    end = 1.0 + BEYOND
    # the take's profile reaches max_shift further at both ends (and, for a lip that may
    # shorten, a crease's width further towards the slit, to tell a crease from an open mouth)
    past = CREASE_PX / np.linalg.norm(take.direction) if params.shrink > 0.0 else 0.0
    t2, r2, xyz2, _ = lip_profile(
        img_t, take.origin, take.direction, min(take.t, 0.0) - params.max_shift - past,
        end + params.max_shift,
    )  # fmt: skip
    edge_t = vermilion_edge(r2, t2, 1.0, params.search, end)
    if edge_t is None or edge_t[1] < params.min_contrast:
        return NO_BORDER
    arc_t = arc_length(t2, xyz2, edge_t[0])
    # the border's neighbourhood: the lip's outer half and the skin beyond (the slit's side
    # may roll out of sight or show the mouth)
    near = (arc_n >= -NEAR * lip_length) & (t >= min(neutral.t, 0.0))
    shift = register_redness(arc_n[near], r[near], arc_t, r2, params.search * lip_length)
    if shift is None:
        return NOT_MATCHED
    if params.shrink > 0.0 and length < 0.0:
        # a lip that shortens as it rounds (the lower lip): where the take's surface ends
        # towards the slit is the slit, and the lip's vertices keep their share of its length;
        # a closed mouth (the surface resumes past a crease) keeps the flow's answer
        ends = np.flatnonzero(np.isfinite(arc_t))[0]
        crease = int(np.ceil(CREASE_PX / (np.linalg.norm(take.direction) * (t2[1] - t2[0]))))
        if ends == 0 or np.isfinite(xyz2[max(ends - crease, 0) : ends]).all(axis=1).any():
            return take.at, min(contrast, edge_t[1])
        reach = shift - arc_t[ends]
        length *= float(np.clip(reach / lip_length, 1.0 - params.shrink, 1.0))
    target = length + shift
    flow = np.interp(take.t, t2, arc_t)
    tol = params.stretch * abs(length) + FLOOR_MM
    goal = float(np.clip(flow, target - tol, target + tol)) if np.isfinite(flow) else target
    ok = np.isfinite(arc_t)
    if not arc_t[ok].min() <= goal <= arc_t[ok].max():
        return NO_SURFACE  # the surface ends (or the profile does) before the length is walked
    place = float(np.interp(goal, arc_t[ok], t2[ok]))
    if abs(place - take.t) > params.max_shift:  # the correction, in shares of the lip's height
        return TOO_FAR
    return take.origin + place * take.direction, min(contrast, edge_t[1])
