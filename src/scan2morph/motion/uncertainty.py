"""Click-noise sensitivity of the viseme motion: an error bar that needs no ground truth.

The template is fitted to landmarks clicked by hand (or by a detector), and the spline carries
their imprecision into every vertex (:func:`scan2morph.template.noise_gain`). The neutral's and a
viseme's clicks are independent, so the motion between them carries a false part that does not
shrink with the motion: a small viseme ("she", "eel") can be dominated by it. This module
measures that part for a subject's own data: it repeats the fits of the neutral and of each
viseme with their landmarks perturbed by Gaussian noise of the stated click precision, keeps the
pipeline's alignment, mask and smoothing, and reports how far the final motion moves.

On the synthetic cohort the estimate is checked against the error that the ground truth shows
(``accuracy.json``: ``click_noise_relative`` beside ``relative_error``).
"""

from __future__ import annotations

import logging
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from scan2morph.align.rigid import transform_points
from scan2morph.errors import InputError
from scan2morph.motion.clicks import ClickedTake, clicked_take
from scan2morph.motion.precision import resolve_click_noise
from scan2morph.motion.smooth import Relief, laplacian_smooth
from scan2morph.motion.vectors import motion_vectors
from scan2morph.store import paths
from scan2morph.template.fit import FitRules, fit_take
from scan2morph.template.rim import Rim

log = logging.getLogger(__name__)

#: ``refiner(take, fit, take_landmarks, neutral_landmarks) -> (vertices, valid, confidence)``: a
#: take's refined correspondence from those clicks (``fit``: :func:`fit_take`'s result for them),
#: in the neutral frame (mm), with the refinement's per-vertex confidence in [0, 1].
Refiner = Callable[[str, dict, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


def noise_datasets(result: Mapping[str, dict]) -> dict[str, np.ndarray]:
    """Store datasets of :func:`click_noise_motion`'s result (see ``schemas/store.layout.yaml``)."""
    data = {paths.viseme(t, "noise_rms_mm"): r["rms_mm"] for t, r in result.items()}
    data[paths.motion_noise("takes")] = np.array(list(result), dtype=object)
    for key in ("relative", "rms_error_mm"):
        data[paths.motion_noise(key)] = np.array([r[key] for r in result.values()], dtype=float)
    failed = [r["failed_draws"] for r in result.values()]
    data[paths.motion_noise("failed_draws")] = np.array(failed, dtype=np.int64)
    return data


def noise_by_take(store: Mapping[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Per viseme, ``relative`` and ``rms_error_mm`` from a store's ``/motion_noise`` datasets
    (the inverse of :func:`noise_datasets`); empty when the store has none."""
    if paths.motion_noise("takes") not in store:
        return {}
    names = [str(n) for n in np.asarray(store[paths.motion_noise("takes")]).tolist()]
    rel = np.asarray(store[paths.motion_noise("relative")], dtype=np.float64)
    err = np.asarray(store[paths.motion_noise("rms_error_mm")], dtype=np.float64)
    return {
        t: {"relative": float(r), "rms_error_mm": float(e)}
        for t, r, e in zip(names, rel, err, strict=True)
    }


def _fit(template, take: ClickedTake, landmarks, recipe: DrawRecipe, source, neutral=None):
    """The take's fit to ``landmarks`` (its forehead rim placed from the ``neutral``'s
    landmarks, when given and ``recipe.rim_share`` < 1): ``(aligned vertices, fit)``."""
    rim = None
    if neutral is not None and recipe.rim_share < 1.0:
        rim = Rim(neutral.landmarks, neutral.fiducial_set, recipe.rim_share)
    mesh = fit_take(
        template,
        landmarks,
        take.xyz,
        fiducial_set=take.fiducial_set,
        rules=recipe.fit_rules,
        source=source,
        rim=rim,
    )
    return transform_points(np.asarray(take.transform, float), mesh["vertices"]), mesh


@dataclass(frozen=True)
class DrawRecipe:
    """How each click-noise draw is made into a motion, as the pipeline makes its own.

    Attributes
    ----------
    fit_rules : FitRules
        The pipeline's fit rules (:func:`fit_take`'s besides the take's data and fiducial set).
    smoothing : mapping
        ``w``, ``iterations``, ``max_stretch`` and ``confidence_relief`` (config ``smoothing``;
        ``inf`` tears nothing; the relief applies to a ``refiner``'s confidence).
    refiner : callable, optional
        ``refiner(take, fit, take_landmarks, neutral_landmarks) -> (vertices, valid,
        confidence)``: the take's correspondence refined against the neutral from those clicks
        and the take's fit to them (:func:`fit_take`'s result, not fitted again; neutral frame,
        mm), when the pipeline refines (:mod:`scan2morph.stages.refine`); the motion of every
        draw is then that of the refined meshes, smoothed with their confidence, as the
        pipeline's is.
    rim_share : float
        A viseme's forehead rim placed from the neutral's with this share of its own spline
        motion (``template.rim_share``; :mod:`scan2morph.template.rim`); 1: the plain spline.
    """

    fit_rules: FitRules
    smoothing: Mapping[str, float]
    refiner: Refiner | None = None
    rim_share: float = 1.0


@dataclass(frozen=True)
class ClickNoise:
    """The click-noise draws of :func:`click_noise_motion`.

    Attributes
    ----------
    px : float
        Standard deviation of the click noise, px per coordinate (> 0).
    draws : int
        Perturbed refits per take (>= 2).
    seed : int
        Seed of the draws (each take has its own stream, seeded by this and the take id).
    """

    px: float
    draws: int
    seed: int


def click_noise_motion(
    template,
    neutral: ClickedTake,
    visemes: Mapping[str, ClickedTake],
    suppressed: np.ndarray,
    recipe: DrawRecipe,
    noise: ClickNoise,
    source: str = "subject",
) -> dict[str, dict]:
    """Spread of each viseme's final motion under landmark click noise.

    Every draw adds independent Gaussian noise of ``click_noise_px`` (per coordinate) to the
    neutral's and to every viseme's landmarks, refits them (:func:`fit_take`, the pipeline's
    options), applies the pipeline's alignment transforms, takes the motion, zeroes it under the
    mask and smooths it as the pipeline does (:func:`laplacian_smooth`), and compares it with the
    motion from the unperturbed landmarks. Because the clicks already carry noise of about that
    size, the spread equals the error that the clicking adds to the motion when the propagation
    is close to linear (as the spline, a linear map of the landmarks, is). A take that brings its
    ``motion`` (the pipeline's, from the same clicks) is not refitted for the reference: the
    refit gives the same numbers, bit for bit (checked on every modality of the default cohort
    and by ``tests/unit/test_motion_noise.py``).

    Parameters
    ----------
    template : Template
        The base template.
    neutral : ClickedTake
    visemes : mapping take -> ClickedTake
    suppressed : (V,) bool
        The stencil mask (``/mask/suppressed``).
    recipe : DrawRecipe
        How a draw is fitted, refined and smoothed.
    noise : ClickNoise
        The click noise (px), the number of draws and their seed.
    source : str
        The subject, for messages.

    Returns
    -------
    dict take -> dict
        ``rms_mm`` (V,) float64: RMS over the draws of the change of the final motion at each
        vertex (0 under the mask; NaN where no draw had a value); ``motion`` (V, 3): the final
        motion from the unperturbed landmarks (the pipeline's ``/visemes/{take}/motion``);
        ``relative``: the RMS of ``rms_mm`` over the unmasked vertices divided by the RMS of the
        motion there (NaN when that motion is zero); ``rms_error_mm``: the former;
        ``motion_rms_mm``: the latter; ``failed_draws``: draws whose perturbed fit of the take
        or of the neutral was refused (folded template, a fiducial outside the image), or whose
        refinement refused the take (a detected take's fit not its skin), left out.
        Every take has its own noise stream (seeded by ``seed`` and the take id), so adding or
        removing a take leaves the others' numbers unchanged.

    Raises
    ------
    InputError
        ``noise.px`` <= 0, ``noise.draws`` < 2, a mask of the wrong length, or a take's own
        fit error with its clicks (naming it). Fewer than half of a take's draws fitted (the
        neutral's: every take's) is no error: that take has no error bar (NaN ``rms_mm``,
        ``relative``, ``rms_error_mm``; every draw in ``failed_draws``; a warning says why).
    """
    draws = _checked_draws(noise, source)
    suppressed = np.asarray(suppressed, dtype=bool)
    smooth = _FinalMotion(suppressed, recipe.smoothing)
    n_base, n_mesh = _fit(template, neutral, neutral.landmarks, recipe, f"{source}/neutral")
    faces = n_mesh["faces"]
    if suppressed.shape != (len(n_base),):
        raise InputError(
            source, f"suppressed: expected ({len(n_base)},) mask flags, got {suppressed.shape}"
        )
    if not visemes:
        return {}
    reference = {
        take: _reference(template, take, data, neutral, (n_base, n_mesh), recipe, smooth, source)
        for take, data in visemes.items()
    }
    n_fits, n_problem = _perturbed(template, "neutral", neutral, [0], noise, draws, recipe, source)
    # each draw's viseme fit places its rim from that draw's neutral clicks
    partners = [neutral if f is None else replace(neutral, landmarks=f[2]) for f in n_fits]
    out = {}
    for take, data in visemes.items():
        stream = [1, zlib.crc32(take.encode())]
        t_fits, problem = _perturbed(
            template, take, data, stream, noise, draws, recipe, source, partners
        )  # fmt: skip
        if problem := n_problem or problem:  # the error bar is a diagnostic: the take stays
            log.warning("%s/%s has no click-noise error bar: %s", source, take, problem)
        sq, count, used = np.zeros(len(n_base)), np.zeros(len(n_base), dtype=np.int64), 0
        for n_fit, t_fit in () if problem else zip(n_fits, t_fits, strict=True):
            moved = _draw_motion(recipe.refiner, smooth, take, (n_fit, t_fit), faces, source)
            if moved is None:  # its fit, or its refinement, refused
                continue
            d2 = np.sum((moved - reference[take]) ** 2, axis=1)
            have = np.isfinite(d2)  # a vertex the smoothing could not reach has no value
            sq[have] += d2[have]
            count += have
            used += 1
        out[take] = _spread(sq, count, reference[take], ~suppressed) | {
            "failed_draws": draws - used
        }
    return out


def _draw_motion(refiner, smooth, take, fits, faces, source):
    """One draw's final motion of a take from its and its neutral's perturbed ``fits``; None
    when either fit was refused (None) or its refinement refuses it (a detected take's fit not
    its skin): the draw is left out."""
    n_fit, t_fit = fits
    if n_fit is None or t_fit is None:
        return None
    where = f"{source}/{take} (click-noise draw)"
    try:
        v, valid, conf = _corresponded(refiner, take, t_fit, t_fit[2], n_fit[2])
    except InputError as err:
        log.info("%s: draw not refined, left out: %s", where, err)
        return None
    return smooth(v, valid, conf, n_fit[0], n_fit[1]["valid"], faces, where)


def _reference(
    template, take, data: ClickedTake, neutral: ClickedTake, n_fit, recipe, smooth, source
):
    """A viseme's final motion from its unperturbed clicks: the pipeline's own when the take
    brings it (no refit), else refitted, refined and smoothed as the pipeline does."""
    if data.motion is not None:
        return np.asarray(data.motion, dtype=np.float64)
    n_base, n_mesh = n_fit
    t_fit = _fit(template, data, data.landmarks, recipe, f"{source}/{take}", neutral)
    v, valid, conf = _corresponded(recipe.refiner, take, t_fit, data.landmarks, neutral.landmarks)
    return smooth(v, valid, conf, n_base, n_mesh["valid"], n_mesh["faces"], take)


def _checked_draws(noise: ClickNoise, source: str) -> int:
    """The number of draws, after checking the noise's size and count."""
    if not (np.isfinite(noise.px) and noise.px > 0):
        raise InputError(source, f"click_noise_px: expected > 0 px, got {noise.px}")
    if int(noise.draws) != noise.draws or noise.draws < 2:
        raise InputError(source, f"draws: expected an integer >= 2, got {noise.draws}")
    return int(noise.draws)


class _FinalMotion:
    """A take's final motion as the pipeline makes it: motion vectors, then the masked
    Laplacian smoothing (``smoothing``: ``w``, ``iterations``, ``max_stretch``,
    ``confidence_relief``)."""

    def __init__(self, suppressed: np.ndarray, smoothing: Mapping[str, float]):
        self.suppressed = suppressed
        self.w, self.iterations = float(smoothing["w"]), int(smoothing["iterations"])
        self.max_stretch = float(smoothing["max_stretch"])
        self.relief = float(smoothing["confidence_relief"])

    def __call__(self, aligned, valid, confidence, base, base_valid, faces, where) -> np.ndarray:
        raw = motion_vectors(
            aligned,
            base,
            valid,
            base_valid,
            source=where,
            faces=faces,
            max_stretch=self.max_stretch,
        )
        return laplacian_smooth(
            raw,
            faces,
            w=self.w,
            iterations=self.iterations,
            fixed=self.suppressed,
            missing=~np.isfinite(raw).all(axis=1),
            source=where,
            relief=Relief(confidence, self.relief),
        )


def _corresponded(refiner, take, t_fit, t_landmarks, n_landmarks):
    """The take's vertices, validity and correspondence confidence compared with the neutral's:
    its aligned fit (no confidence), or its refined mesh."""
    if refiner is None:
        return t_fit[0], t_fit[1]["valid"], None
    return refiner(take, t_fit[1], t_landmarks, n_landmarks)


def _perturbed(
    template, name, data, stream, noise: ClickNoise, draws, recipe, source, partners=None
) -> tuple[list, str]:
    """The take's ``draws`` fits with perturbed clicks (None where refused), each with its
    clicks; its own noise stream (``noise.seed`` and ``stream``); ``partners``: each draw's
    neutral (its clicks), whose rim a viseme's fit follows. Also why the take has no error bar:
    fewer than half of its draws fitted (the noise is too large for the template; quoting the
    first refusal), else ``""``."""
    rng = np.random.default_rng([int(noise.seed), *stream])
    fits, first = [], None
    for k in range(draws):
        noisy = data.landmarks + noise.px * rng.standard_normal(np.shape(data.landmarks))
        try:
            partner = None if partners is None else partners[k]
            fit = _fit(template, data, noisy, recipe, f"{source}/{name}", partner)
            fits.append((*fit, noisy))
        except InputError as err:
            fits.append(None)
            first = first or f"draw {k}: {err}"
    done = sum(f is not None for f in fits)
    if done < max(2, draws / 2):
        return fits, (
            f"click_noise_px {noise.px:g}: only {done} of {draws} perturbed fits of {name} "
            f"succeeded (the noise is too large for the template; first refusal, {first})"
        )
    return fits, ""


def _spread(sq: np.ndarray, count: np.ndarray, motion: np.ndarray, free: np.ndarray) -> dict:
    """A take's per-vertex RMS change over the draws and its share of the motion."""
    rms = np.full(len(sq), np.nan)
    rms[count > 0] = np.sqrt(sq[count > 0] / count[count > 0])
    moving = free & np.isfinite(motion).all(axis=1)
    where = moving & np.isfinite(rms)
    err = float(np.sqrt(np.mean(rms[where] ** 2))) if where.any() else float("nan")
    # a take without an error bar (no draw fitted): the motion's RMS all the same
    over = where if where.any() else moving
    ref = float(np.sqrt(np.mean(np.sum(motion[over] ** 2, axis=1)))) if over.any() else 0.0
    return {
        "rms_mm": rms,
        "motion": motion,
        "relative": err / ref if ref > 0 else float("nan"),
        "rms_error_mm": err,
        "motion_rms_mm": ref,
    }


def subject_motion_noise(
    template,
    store: Mapping[str, np.ndarray],
    neutral: str,
    visemes: Sequence[str],
    fiducial_sets: Mapping[str, str],
    recipe: DrawRecipe,
    settings: Mapping[str, object],
    source: str = "subject",
) -> tuple[dict[str, np.ndarray], dict[str, dict], dict]:
    """The motion_noise stage of one subject: click precision, then the error bar.

    Parameters
    ----------
    template : Template
        The base template.
    store : mapping store path -> array
        The subject's repaired range images, landmarks, alignment and ``/mask/suppressed``
        (:func:`scan2morph.motion.clicks.clicked_take`).
    neutral : str
    visemes : sequence of str
    fiducial_sets : mapping take -> fiducial set
    recipe : DrawRecipe
        As :func:`click_noise_motion`'s.
    settings : mapping
        The config section ``motion_noise``: ``click_noise_px`` (px or ``"auto"``),
        ``fallback_px``, ``stable_points``, ``draws``, ``seed`` (and ``refine_draws``: the draws
        with a ``recipe.refiner``, each of which refines every viseme).
    source : str
        The subject, for messages.

    Returns
    -------
    datasets : dict
        :func:`noise_datasets` plus ``/motion_noise/click_noise_px`` (the value used),
        ``/motion_noise/click_noise_measured_px`` (NaN when not measurable) and
        ``/motion_noise/stable_points``.
    result : dict
        :func:`click_noise_motion`'s.
    noise : dict
        :func:`scan2morph.motion.precision.resolve_click_noise`'s.
    """
    takes = {t: clicked_take(store, t, fiducial_sets[t]) for t in [neutral, *visemes]}
    points = [int(p) for p in settings["stable_points"]]
    # detected takes' stable points were carried over from the neutral: their precision is
    # measured on the detector's own points
    placed = {
        t: replace(c, landmarks=store.get(paths.landmark_detected(t), c.landmarks))
        for t, c in takes.items()
    }
    noise = resolve_click_noise(
        settings["click_noise_px"],
        placed,
        points,
        settings["fallback_px"],
        recipe.fit_rules.max_slope_deg,
        source,
    )
    noise["note"] += detected_note(store, list(takes))
    draws = settings["draws"] if recipe.refiner is None else settings["refine_draws"]
    result = click_noise_motion(
        template,
        takes[neutral],
        {t: takes[t] for t in visemes},
        store[paths.mask("suppressed")],
        recipe,
        ClickNoise(noise["click_noise_px"], draws, settings["seed"]),
        source=source,
    )
    data = noise_datasets(result)
    data[paths.motion_noise("click_noise_px")] = np.float64(noise["click_noise_px"])
    data[paths.motion_noise("click_noise_measured_px")] = np.float64(noise["measured_px"])
    data[paths.motion_noise("stable_points")] = np.array(points, dtype=np.int64)
    return data, result, noise


def detected_note(store: Mapping[str, np.ndarray], takes: Sequence[str]) -> str:
    """What the measured click noise means when some of ``takes`` had their landmarks detected
    (``""`` when none had): the detector's scatter across the takes, not its bias.

    A detector that misplaces a point alike on every take of a face (a face unlike its
    training faces) scatters little across them, so the noise measured and the error bar
    drawn from it are small while the fit sits off; only the detected points themselves (the
    report's takes figure) show that.
    """
    detected = [t for t in takes if paths.landmark_detected(t) in store]
    if not detected:
        return ""
    return (
        f"; {len(detected)} of {len(takes)} takes' landmarks were detected: for those this is "
        "the detector's scatter across the takes, not its bias, which no error bar here shows "
        "(check the detected points in the takes figure)"
    )
