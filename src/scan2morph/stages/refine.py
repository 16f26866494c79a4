"""Refine: each take's correspondence to the neutral corrected by image correlation of the skin
(:mod:`scan2morph.refine`), then aligned as the take was: the meshes the motion stage compares.

``refine.method: flow`` (the default) runs it; ``none`` keeps the paper's template-fit
correspondence (the motion stage then reads the aligned fits, and this stage is not run).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from contextlib import nullcontext
from dataclasses import dataclass, fields, replace

import numpy as np

from scan2morph.align import IcpParams, rotation_angle_deg
from scan2morph.errors import InputError
from scan2morph.io.mesh_scan import SHADED
from scan2morph.refine import RefineParams, grey, refine_channels, shape_channels, texture_channel
from scan2morph.refine.carried import carried_start
from scan2morph.refine.jaw import ChinMeshes, JawParams, JawPrior, chin_weights, jaw_prior
from scan2morph.refine.lip import LipImages, LipParams, LipPrior, lip_prior
from scan2morph.refine.memo import active, sharing
from scan2morph.refine.shape import ShapeParams
from scan2morph.stages import align as align_stage
from scan2morph.stages import fit as fit_stage
from scan2morph.stages.part import Part, Run, Take, need
from scan2morph.stages.take_mesh import CARRY_UPPER, carries_upper, sample_points, steep_skin
from scan2morph.store import paths
from scan2morph.store.warnings import landmark_source, text_value
from scan2morph.template import Template, subdivide_template
from scan2morph.template.fit import fit_map
from scan2morph.template.regions import icp_region, lip
from scan2morph.template.sample import sample_mesh

#: Config sections this stage reads (``template`` for the subdivision level and sampling rules,
#: ``align`` for the ICP settings of the jaw prior).
SECTIONS = ("refine", "template", "align")
#: The last iBUG number of the jaw line (1-17: outline points, not skin points).
JAW_LINE = 17
#: A take's texture correlation stops after a round that measured less than this share of
#: ``refine.min_confident_share``: it is taken as not correlating (its rounds measure about the
#: same share; the shape refines it, where ``refine.shape.use``).
GIVE_UP = 0.5
#: Why a detected take whose refinement would move its skin too far is left out: the template fit
#: it would keep rests on those landmarks (a head turned 30 degrees from its neutral: the mouth
#: detected on the nose, 16.7 times the smile's motion in error, kept in the models).
DETECTION_FAILED = (
    "its template fit rests on those landmarks, so none of it is known to be its skin: give "
    "this take's landmarks in the sheet (its detected ones, to correct: {pts})"
)
#: ``refine.method`` values: image-correlation refinement, or the template fit as it is.
METHODS = ("flow", "none")
#: The config keys of the slope limits of a carried or turned take's skin (:class:`Params`).
STEEP_KEYS = ("max_unmeasured_slope_deg", "max_measured_slope_deg")
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Refinement parameters.

    Attributes
    ----------
    method : str
        One of :data:`METHODS`.
    levels : int
        Template subdivisions.
    min_weight, max_slope_deg : float
        The fit's sampling rules (``template.sample_min_weight``, ``template.max_slope_deg``).
    fit : scan2morph.stages.fit.Params
        The fit's parameters (each take kind's fiducial set: the soft constraints).
    min_confident_share : float
        A take whose share of confidently measured vertices is below this keeps its template
        fit (``refine.min_confident_share``), with a warning.
    flow : RefineParams
        The image correlation's settings of the section ``refine``.
    jaw : JawParams
        The jaw prior's (``refine.jaw``; :mod:`scan2morph.refine.jaw`).
    lip : LipParams
        The upper-lip prior's (``refine.lip``; :mod:`scan2morph.refine.lip`).
    lower_lip : LipParams
        The lower lip's: ``refine.lip``'s settings with ``refine.lower_lip`` over them.
    icp : IcpParams or None
        The alignment's ICP settings (``align.icp``: the jaw prior's registration); None: the
        defaults.
    still_region : str
        ``align.icp_region``: the skin the alignment holds still (the jaw prior's reference).
    shape : ShapeParams
        The shape-driven refinement's (``refine.shape``; :mod:`scan2morph.refine.shape`): a
        take whose texture does not correlate with the neutral's.
    texture_unmatched : bool
        Take the texture as not correlating without measuring it, and go straight to the
        shape-driven refinement (not a config key: the click-noise draws of a take whose first
        draw found so; its texture's failed correlation is a quarter of those draws' CPU).
    max_correction_rms_mm : float
        A refinement that would move the skin farther than this from the template fit (RMS
        over the vertices, mm) is not used (``refine.max_correction_rms_mm``): a colour image
        that is not the scan's (another take's) is followed tens of mm off. A take whose
        landmarks were all detected is refused instead (:func:`run`): its fit rests on them.
    carry_upper_face : str
        One of :data:`CARRY_UPPER` (``refine.carry_upper_face``): whose upper face starts from
        the neutral's carried by the take's alignment instead of the take's own landmarks.
    max_unmeasured_slope_deg, max_measured_slope_deg : float or None
        In those takes, a vertex measured nowhere (confidence below
        :data:`~scan2morph.stages.take_mesh.MEASURED`), or one
        measured, on a surface steeper than this (degrees, as ``max_slope_deg``) is invalid, its
        motion filled from its neighbours' (``refine.max_unmeasured_slope_deg``,
        ``refine.max_measured_slope_deg``); None: no such limit.
    turned_view_deg : float or None
        A take seen from a direction more than this from its neutral's once aligned (degrees,
        :func:`~scan2morph.stages.take_mesh.view_turn`) has the same limits
        (``refine.turned_view_deg``; :func:`~scan2morph.stages.take_mesh.steep_skin`); None:
        only the carried takes.
    """

    method: str
    levels: int
    min_weight: float
    max_slope_deg: float | None
    fit: fit_stage.Params
    min_confident_share: float
    flow: RefineParams
    jaw: JawParams = JawParams()
    lip: LipParams = LipParams()
    lower_lip: LipParams = LipParams(prior=False)
    icp: IcpParams | None = None
    still_region: str = "stable"
    shape: ShapeParams = ShapeParams()
    texture_unmatched: bool = False
    max_correction_rms_mm: float = 8.0
    carry_upper_face: str = "doubtful"
    max_unmeasured_slope_deg: float | None = 60.0
    max_measured_slope_deg: float | None = 70.0
    turned_view_deg: float | None = 5.0

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``refine``, ``template`` and ``align``."""
        refine, template, align = config["refine"], config["template"], config["align"]
        names = {f.name for f in fields(RefineParams)}
        jaw = _settings(JawParams, refine, "jaw")
        lip = _settings(LipParams, refine, "lip")
        base = {"prior": False, "shrink": 0.4} | dict(refine.get("lip", {}))
        lower = _settings(LipParams, refine, "lower_lip", base)
        return cls(
            str(refine["method"]),
            int(template["subdivision_levels"]),
            template["sample_min_weight"],
            template["max_slope_deg"],
            fit_stage.Params.from_config(config),
            float(refine.get("min_confident_share", 0.0)),
            RefineParams(**{k: v for k, v in refine.items() if k in names}),
            jaw,
            lip,
            lower,
            align_stage.icp_params(align),
            str(align["icp_region"]),
            _settings(ShapeParams, refine, "shape"),
            max_correction_rms_mm=float(
                refine.get("max_correction_rms_mm", cls.max_correction_rms_mm)
            ),
            carry_upper_face=str(refine.get("carry_upper_face", cls.carry_upper_face)),
            **{k: _degrees(refine.get(k, getattr(cls, k))) for k in STEEP_KEYS},
            turned_view_deg=_degrees(refine.get("turned_view_deg", cls.turned_view_deg)),
        )

    def __post_init__(self) -> None:
        if (which := self.carry_upper_face) not in CARRY_UPPER:
            expected = ", ".join(CARRY_UPPER)
            raise InputError(
                "refine", f"carry_upper_face: expected one of {expected}, got {which!r}"
            )
        for key in STEEP_KEYS:
            limit = getattr(self, key)
            if limit is not None and not 0.0 < limit < 90.0:
                raise InputError(
                    "refine", f"{key}: expected degrees in (0, 90) or None, got {limit}"
                )
        if (turn := self.turned_view_deg) is not None and not 0.0 <= turn < 180.0:
            raise InputError(
                "refine", f"turned_view_deg: expected degrees in [0, 180) or None, got {turn}"
            )


def _degrees(value) -> float | None:
    """A slope limit: degrees, or None (no limit)."""
    return None if value is None else float(value)


def _settings(kind, refine: Mapping, name: str, base: Mapping | None = None):
    """``kind`` (:class:`JawParams`, :class:`LipParams` or :class:`ShapeParams`) from the
    section ``refine.{name}`` over ``base``; its own check's problem named by the config key."""
    try:
        return kind(**(dict(base or {}) | dict(refine.get(name, {}))))
    except InputError as exc:
        raise InputError("config", f"refine.{name}: {exc.problem}") from None


def enabled(refine: Mapping) -> bool:
    """Whether the config section ``refine`` asks for the refinement."""
    return refine.get("method", "none") != "none"


def shape_verdicts(data: Mapping, takes) -> dict[str, bool]:
    """The pipeline's refinement of each of ``takes`` in ``data`` (its refine group's
    attributes, a mapping under ``paths.refine_group(take)``): whether its texture did not
    correlate and the surface's shape refined it (``shape_used``); a take without them is not
    named."""
    out = {}
    for take in takes:
        attrs = data.get(paths.refine_group(take))
        if isinstance(attrs, Mapping) and "shape_used" in attrs:
            out[take] = bool(attrs["shape_used"])
    return out


def run(template: Template, take: Take, params: Params) -> Part:
    """Refine one take's correspondence to the neutral.

    Parameters
    ----------
    template : Template
        The base template.
    take : Take
        Its ``kind``, ``neutral`` (the neutral is its own reference: its refined mesh is its
        aligned fit) and ``data`` (the repair, fit and align parts of the take and the repair
        and fit parts of the neutral).
    params : Params

    Returns
    -------
    Part
        ``refine/vertices`` (V, 3) mm in the neutral frame (NaN where invalid), ``refine/valid``
        (V,), ``refine/points2d`` (V, 2) px in the take's image and ``refine/confidence`` (V,)
        (the flow's, 0 where the fit was kept, plus the share the jaw prior moved a chin vertex
        by and, on the upper lip, the lip prior's weight times one minus that);
        the ``refine`` group's attributes hold the median correction (px), the share of
        vertices with a confident measurement, whether the flow was ``used`` and, when not,
        the ``problem``; whether the take's texture did not correlate and the surface's shape
        refined it (``shape_used``, :mod:`scan2morph.refine.shape`); whether the jaw prior was
        used (``jaw_used``), why not
        (``jaw_problem``, ``"off"`` with ``refine.jaw.prior`` false), the rigidity gate's share
        of it (``jaw_share``) and, when the chin was registered, ``jaw_rmse_mm``,
        ``jaw_rmse_limit_mm`` and ``jaw_angle_deg``; whether the
        upper-lip prior was used (``lip_used``), why not (``lip_problem``), the lip's vertices
        and those placed (``lip_vertices``, ``lip_measured``) and the median redness step at
        its border (``lip_contrast``).

    Raises
    ------
    InputError
        A take whose landmarks were all detected and whose refinement would move its skin
        farther than ``params.max_correction_rms_mm`` from its template fit: the fit rests on
        those landmarks, so the take is left out (:mod:`scan2morph.stages.failure`); a take
        with given landmarks keeps its fit instead, with the ``problem`` named.
    """
    name, neutral, data, source = take.take, take.neutral, take.data, take.source
    aligned = need(data, paths.align(name, "vertices"), source)
    valid = np.asarray(need(data, paths.mesh(name, "valid"), source), dtype=bool)
    points = np.asarray(need(data, paths.mesh(name, "points2d"), source), dtype=np.float64)
    if name == neutral:
        out = {
            "vertices": aligned,
            "valid": valid,
            "points2d": points,
            "confidence": np.ones(len(valid)),
        }
        return Part({paths.refine(name, k): v for k, v in out.items()})
    # the steps a refinement repeats on the same data (the reference's high-pass in every
    # round, the splines' warps) computed once, bit for bit (a click-noise draw's scope is
    # kept: it shares them across the takes)
    with nullcontext() if active() else sharing():
        return _refine(template, take, params)


def _refine(template: Template, take: Take, params: Params) -> Part:
    """:func:`run` for a take other than the neutral."""
    name, kind, neutral, data, source = take.take, take.kind, take.neutral, take.data, take.source
    points = np.asarray(need(data, paths.mesh(name, "points2d"), source), dtype=np.float64)
    fine = subdivide_template(template, params.levels)
    sets = {t: params.fit.fiducial_set(k) for t, k in ((neutral, "neutral"), (name, kind))}
    rims = {neutral: None, name: params.fit.rim(take)}
    maps = [
        fit_map(template, need(data, paths.landmarks(t), source), sets[t], source, rim=rims[t])
        for t in (neutral, name)
    ]
    anchors = _anchors(template, sets[name], source)
    carried = carries_upper(data, (name, neutral), params.carry_upper_face) and _carried(
        template, data, (name, neutral), sets[name], maps, anchors, source
    )
    if carried:
        maps[1], anchors = carried
    refined, report, problem = _flow(fine, name, neutral, data, maps, anchors, params, source)
    if not problem and (problem := _too_far(data, name, refined, fine.faces, params, source)):
        if landmark_source(data, name) == "detected":  # stages.landmarks.DETECTED
            pts = f"results/{take.subject}/landmarks/{name}.pts"
            raise InputError(source, f"{problem}; {DETECTION_FAILED.format(pts=pts)}")
    if problem:
        log.warning("%s: refinement not used: %s", source, problem)
        refined = points
        # the points are the fit's: nothing was measured at them (the motion stage smooths
        # them as it smooths a fit's)
        report["confidence"] = np.zeros(len(points))
    neutral_points = maps[0](fine.vertices)  # the neutral's skin points, px
    jaw = _jaw(template, fine, name, neutral, data, neutral_points, params, source)
    if veto := jaw.contradiction(refined, report["confidence"]):
        jaw = jaw.refused(veto)
    if jaw.used:  # the geometry's answer where the texture gave none
        refined, report["confidence"] = jaw.fill(refined, report["confidence"])
    elif params.jaw.prior:
        log.info("%s: jaw prior not used: %s", source, jaw.problem)
    refined, priors = _lips(fine, take, neutral_points, refined, report, params)
    steep = steep_skin(data, (name, neutral), params, source)
    confidence = report["confidence"] if steep else None
    vertices, ok = sample_points(data, name, refined, fine.faces, params, source, confidence)
    attrs = _attrs(params, problem, report, ok, jaw, priors) | {"upper_carried": bool(carried)}
    log.info("%s: refined %s", name, attrs)
    return Part(
        {
            paths.refine(name, "vertices"): vertices,
            paths.refine(name, "valid"): ok,
            paths.refine(name, "points2d"): refined,
            paths.refine(name, "confidence"): report["confidence"],
        },
        attrs={paths.refine_group(name): attrs},
    )


def _carried(template, data, takes, fiducials: str, maps, anchors, source: str):
    """The take's map and anchors with its upper face carried from the neutral
    (:func:`~scan2morph.refine.carried.carried_start`); None when the take failed its
    alignment's gate or the carry found nothing (a warning: its own points place it)."""
    if not bool(np.asarray(data.get(paths.align(takes[0], "ok"), True))):
        return None
    xyz = [need(data, paths.range_image(t, "xyz"), source) for t in takes]
    move = need(data, paths.align(takes[0], "transform"), source)
    lm = need(data, paths.landmarks(takes[0]), source)
    start = carried_start(template, lm, fiducials, maps[0], xyz, move, anchors, source)
    if start is None:
        log.warning("%s: upper face not carried: no neutral point found on its surface", source)
    return start


def _too_far(data, name: str, refined: np.ndarray, faces, params: Params, source: str) -> str:
    """Why a refinement that would move the skin implausibly far from the take's template fit
    is not used (RMS over the vertices valid in both above ``params.max_correction_rms_mm``:
    1.4-3.4 mm on the default cohort, 20.7 mm for a smile given the car's colour image); ""."""
    moved, ok = sample_points(data, name, refined, faces, params, source)
    fit = np.asarray(need(data, paths.align(name, "vertices"), source), dtype=np.float64)
    both = ok & np.isfinite(fit).all(axis=1) & np.isfinite(moved).all(axis=1)
    if not both.any():
        return ""
    rms = float(np.sqrt(np.mean(np.sum((moved[both] - fit[both]) ** 2, axis=1))))
    if rms <= params.max_correction_rms_mm:
        return ""
    # with detected landmarks these are far off more often than an image is another take's (a
    # head turned 30 degrees from its neutral: the mouth detected on the nose, 13 mm)
    cause = (
        "the detected landmarks are far off (a turned or unusual face?), or the colour image "
        "does not follow the range data"
        if "detected" in landmark_source(data, name)
        else "the colour image does not follow the range data (another take's image?)"
    )
    return (
        f"it would move the skin {rms:.1f} mm RMS from the template fit (more than "
        f"refine.max_correction_rms_mm {params.max_correction_rms_mm:g}): {cause}"
    )


def _lips(fine, take: Take, neutral_points, refined, report, params: Params) -> tuple:
    """Both lips' priors applied to a take's refined points (each lip's length, the lower
    one's share of it, where its rolling misleads the flow): ``(points, priors)``, with
    ``report["confidence"]`` updated and ``priors`` ``lip`` and ``lower_lip`` ->
    :class:`~scan2morph.refine.lip.LipPrior`."""
    name, neutral, data, source = take.take, take.neutral, take.data, take.source
    priors = {}
    shaded = _shaded(data, (neutral, name))
    for side, settings in (("upper", params.lip), ("lower", params.lower_lip)):
        prior = _lip(
            fine, side, name, neutral, data, neutral_points, refined, params, settings, source,
        ) if not (shaded and settings.prior) else LipPrior.unused(
            len(fine.vertices), f"{shaded}: the lip's border is found by its colour"
        )  # fmt: skip
        if prior.used:
            refined, report["confidence"] = prior.apply(refined, report["confidence"])
        elif settings.prior:
            log.info("%s: %s-lip prior not used: %s", source, side, prior.problem)
        priors["lip" if side == "upper" else "lower_lip"] = prior
    return refined, priors


def _attrs(params: Params, problem: str, report, ok, jaw: JawPrior, priors) -> dict:
    """The ``refine`` group's attributes (see :func:`run`)."""
    attrs = {
        "method": params.method,
        "used": not problem,
        "problem": problem,
        "median_correction_px": report["median_correction_px"],
        "confident_share": report["confident_share"],
        "shape_used": bool(report.get("shape", False)) and not problem,
        "valid_share": float(ok.mean()),
        "jaw_used": jaw.used,
        "jaw_problem": jaw.problem,
        "jaw_share": jaw.share,
    }
    for key, prior in priors.items():
        attrs |= {
            f"{key}_used": prior.used,
            f"{key}_problem": prior.problem,
            f"{key}_vertices": prior.vertices,
            f"{key}_measured": prior.measured,
            f"{key}_contrast": prior.contrast,
        }
    if jaw.motion is not None:
        attrs |= {
            "jaw_rmse_mm": jaw.motion.residual_rmse,
            "jaw_rmse_limit_mm": jaw.motion.rmse_limit,
            "jaw_angle_deg": rotation_angle_deg(jaw.motion.transform),
        }
    return attrs


def _shaded(data: Mapping[str, np.ndarray], takes) -> str:
    """Which of ``takes`` are geometry-only (``camera/color_source`` is :data:`SHADED`), as
    the start of a message; ``""`` when none."""
    names = []
    for t in dict.fromkeys(takes):
        if text_value(data.get(paths.camera(t, "color_source"), "")) == SHADED:
            names.append(t)
    if not names:
        return ""
    verb = "is a geometry-only scan" if len(names) == 1 else "are geometry-only scans"
    return f"{' and '.join(names)} {verb} (no texture or colours: rendered with shading)"


def _anchors(template, fiducials, source: str) -> np.ndarray:
    """The take's fiducials that pin skin points: the jaw-line points (iBUG 1-17) sit on the
    face's outline, not on fixed skin points, and are no constraint on where the skin went."""
    numbers, base = template.fiducial_set(fiducials, source)
    return base[numbers > JAW_LINE]


def _flow(fine, take, neutral, data, maps, anchors, params: Params, source: str):
    """The image correlation of the take's skin against the neutral's
    (:func:`~scan2morph.refine.refine_channels` on the texture): ``(points, report,
    problem)``, ``problem`` saying why the points are not to be used (``""`` when they are);
    a texture given up after a round (:data:`GIVE_UP`) is one that does not correlate. Where
    the texture does not correlate, the surface's shape with whatever texture correlates
    (:func:`_by_shape`), when ``refine.shape.use``; ``report["shape"]`` says whether it did. A
    geometry-only scan keeps its fit."""
    shaded = _shaded(data, (neutral, take))
    if shaded:  # no skin texture to correlate: the shading follows the geometry, not the skin
        report = {"median_correction_px": 0.0, "confident_share": 0.0, "shape": False}
        jaw = " (the jaw prior may still move the chin)" if params.jaw.prior else ""
        kept = "texture-driven refinement is not available, the template fit is kept"
        return None, report, f"{shaded}: {kept}{jaw}"
    images = [grey(need(data, paths.range_image(t, "color"), source)) for t in (neutral, take)]
    texture = [texture_channel(*images, params.flow)]
    if params.texture_unmatched and params.shape.use:
        report = {"median_correction_px": np.nan, "confident_share": np.nan, "shape": False}
        kept = "its texture was taken as not correlating with the neutral's"
    else:
        # a texture whose share after a round is below half the threshold will not reach it
        refined, report = refine_channels(
            fine.vertices,
            fine.faces,
            maps,
            texture,
            anchors,
            params.flow,
            give_up_share=GIVE_UP * params.min_confident_share,
        )
        report["shape"] = False
        if report["confident_share"] >= params.min_confident_share:
            return refined, report, ""
        # the two images do not share the skin's texture (another light, paint, camera or
        # modality): the texture's measurement is not to be trusted
        kept = (
            f"only {100 * report['confident_share']:.0f}% of the face correlates with the "
            f"neutral's texture (refine.min_confident_share "
            f"{100 * params.min_confident_share:.0f}%)"
        )
    if params.shape.use:
        refined, by_shape = _by_shape(fine, (take, neutral), data, maps, anchors, texture, params)
        if by_shape["confident_share"] >= params.shape.min_confident_share:
            log.info("%s: %s: refined by the surface's shape", source, kept)
            return refined, by_shape | {"texture_confident_share": report["confident_share"]}, ""
        kept += (
            f", and only {100 * by_shape['confident_share']:.0f}% by its shape "
            f"(refine.shape.min_confident_share {100 * params.shape.min_confident_share:.0f}%)"
        )
    priors = "".join(
        f" (the {name} prior may still move the {what})"
        for name, what, on in (
            ("jaw", "chin", params.jaw.prior),
            ("lip", "upper lip", params.lip.prior),
            ("lower-lip", "lower lip", params.lower_lip.prior),
        )
        if on
    )
    return None, report, f"{kept}: the template fit is kept{priors}"


def _by_shape(fine, takes, data, maps, anchors, texture: list, params: Params):
    """The refinement by the surface's shape (:mod:`scan2morph.refine.shape`) and the
    ``texture`` channels (the skin's, where it correlates):
    ``(points, report)`` of :func:`~scan2morph.refine.refine_channels`, ``report["shape"]``
    True. ``takes`` are the take's and the neutral's names."""
    take, neutral = takes
    sources = [paths.range_image(t, "xyz") for t in (neutral, take)]
    xyz = [need(data, s, s) for s in sources]
    transform = need(data, paths.align(take, "transform"), take)
    channels = shape_channels(*xyz, transform, texture, params.shape, sources)
    flow = replace(params.flow, fade_px=params.shape.fade_px)
    refined, report = refine_channels(
        fine.vertices, fine.faces, tuple(maps), channels, anchors, flow
    )
    return refined, report | {"shape": True}


def _jaw(template, fine, take, neutral, data, neutral_points, params: Params, source: str):
    """The jaw prior of a take (:mod:`scan2morph.refine.jaw`), or why there is none.

    The neutral's mesh is sampled here from its range image at ``neutral_points`` (its fit's
    pixels, (V, 2)): a click-noise draw refits the neutral with other clicks."""
    if not params.jaw.prior:
        return JawPrior.unused(len(fine.vertices), "off")
    weights = chin_weights(fine.vertices, template.ibug_xy, params.jaw.start, params.jaw.end)
    neutral_vertices, neutral_valid = sample_mesh(
        need(data, paths.range_image(neutral, "xyz"), source),
        neutral_points,
        fine.faces,
        source,
        params.min_weight,
        params.max_slope_deg,
    )
    meshes = ChinMeshes(
        neutral_vertices,
        neutral_valid,
        need(data, paths.align(take, "vertices"), source),
        np.asarray(need(data, paths.mesh(take, "valid"), source), dtype=bool),
        weights,
        icp_region(fine, params.still_region),
    )
    return jaw_prior(
        meshes,
        need(data, paths.range_image(take, "xyz"), source),
        need(data, paths.align(take, "transform"), source),
        params.icp,
        params.jaw.max_rmse_ratio,
        source,
        params.jaw.fade_rmse_ratio,
    )


def _lip(
    fine, side, take, neutral, data, neutral_points, take_points, params: Params, settings, source
):
    """A lip's prior in a take (:mod:`scan2morph.refine.lip`: ``settings`` are
    ``params.lip`` or ``params.lower_lip``), or why there is none."""
    n = len(fine.vertices)
    if not settings.prior:
        return LipPrior.unused(n, "off")
    images = LipImages(
        need(data, paths.range_image(neutral, "color"), source),
        need(data, paths.range_image(neutral, "xyz"), source),
        need(data, paths.range_image(take, "color"), source),
        need(data, paths.range_image(take, "xyz"), source),
        params.min_weight,
        params.max_slope_deg,
    )
    return lip_prior(
        lip(fine, side),
        fine.vertices,
        neutral_points,
        take_points,
        images,
        fine.faces,
        settings,
        source,
    )


def apply(data: Mapping[str, np.ndarray], run_: Run) -> dict[str, np.ndarray]:
    """Every take of a subject held in memory (nothing when ``refine.method`` is ``none``): its
    datasets and its refine group's attributes (a mapping under
    :func:`~scan2morph.store.paths.refine_group`, which the consensus and the click-noise draws
    read as they read them from the part)."""
    if not enabled(run_.config["refine"]):
        return {}
    params = Params.from_config(run_.config)
    out = {}
    for take in run_.subject.kinds:
        part = run(run_.template, Take.of(run_.subject, take, data=data), params)
        out |= part.datasets | part.attrs
    return out
