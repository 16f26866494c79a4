"""Quality gates: one list of warnings per subject, and which takes the models leave out.

Every stage that can go quietly wrong records how it went (ICP convergence, fitness and RMSE;
folded triangles and valid share of a fit; refused refits and click precision of the error bar).
This module turns those records into one list of warnings, written to the store (``/warnings``),
shown first in the report and copied into ``accuracy.json``. A take whose alignment failed its
gate is left out of the models (motion, PCA, modal coordinates) unless the config's
``quality.include_failed_takes`` says otherwise: a model built on a misaligned take moves the
whole face.
"""

from __future__ import annotations

import json
from collections.abc import Mapping

import h5py
import numpy as np

from scan2morph.evaluate import face_region
from scan2morph.geometry import finite_points
from scan2morph.refine import clipped_share
from scan2morph.stages.take_mesh import view_turn
from scan2morph.store import paths
from scan2morph.store.warnings import (
    Warning,
    landmark_source,
    read_failures,
    read_warnings,
    skipped_stages,
    warning_datasets,
)

#: The warning of a take whose colour image is grey-scale.
GREY = (
    "the colour image is grey-scale: the lip priors, which find the lips by their redness, are "
    "not used, and the refinement correlates grey texture only"
)
#: The warning of a subject whose takes the surface's shape refined (their texture did not
#: correlate with the neutral's), ``{takes}`` listed.
SHAPE_REFINED = (
    "{takes}: refined by the surface's shape, as their texture does not correlate with the "
    "neutral's (other lighting or exposure, another sensor's texture, or a texture too dark or "
    "flat): skin that slides without changing its shape is followed less well (the real "
    "head's range scans with both colour images at 0.3 of their brightness: 3.6 times the "
    "motion error); a neutral whose colour image matches its takes' is refined by the skin"
)
#: The warning of a take whose colour image is clipped (saturated) on more than
#: ``quality.max_clipped_share`` of its face; measured on the real head (``{example}``).
CLIPPED = (
    "the colour image is clipped (a channel at the top of its range) on {share:.1f}% of the "
    "face: over-exposed or lit too brightly, the skin shows no texture there and the "
    "refinement's image correlation follows what is left of it ({example}); expose for the skin"
)
#: :data:`CLIPPED`'s measured example.
CLIPPED_EXAMPLE = (
    "the real head's smile with every image twice as bright, 99% of the face clipped: 0.34 of "
    "its motion in error as a range scan, 0.56 as an RGB-D take, against 0.08 and 0.19"
)
#: The warning of a take whose surface the alignment measured noisier than
#: ``quality.max_noise_mm`` (:func:`_noise_warnings`).
NOISY = (
    "its surface is noisy: {noise:.2f} mm RMS at the template's vertex spacing, as the "
    "alignment measured it (the default cohort's scans 0.05-0.13 mm): its alignment and its "
    "correspondence are less accurate ({example}); scan it from nearer, or give several depth "
    "frames of the take"
)
#: :data:`NOISY`'s measured example.
NOISY_EXAMPLE = (
    "the real head's RGB-D smile seen from 0.6 / 0.9 / 1.2 m: 0.13 / 0.31 / 0.69 mm, 0.21 / "
    "0.39 / 0.97 of its motion in error; from 1.2 m with four depth frames 0.32 mm, 0.53"
)
#: Config section this module reads.
SECTIONS = ("quality",)


def aligned_takes(data: Mapping[str, np.ndarray], takes, include_failed: bool) -> list[str]:
    """The takes whose alignment passed its gate (``/takes/{take}/align/ok``), or all of
    ``takes`` with ``include_failed`` (``quality.include_failed_takes``)."""
    return [t for t in takes if include_failed or bool(data.get(paths.align(t, "ok"), True))]


def modelled(subject, data: Mapping[str, np.ndarray]):
    """The subject restricted to the takes the motion stage modelled (its datasets in ``data``):
    what the stages after it work on."""
    takes = [t for t in subject.visemes if paths.viseme(t, "model") in data]
    takes += [t for t in subject.expressions if paths.expression(t, "displacement") in data]
    return subject.keep(takes)


def subject_warnings(h5: h5py.File, settings: Mapping) -> list[Warning]:
    """Every warning of a subject's merged store.

    Parameters
    ----------
    h5 : h5py.File
        The subject's store (open for reading).
    settings : mapping
        The config section ``quality``: ``include_failed_takes`` (bool), ``max_click_noise_px``
        (px), ``min_valid_fraction`` (share of template vertices with data),
        ``max_view_turn_deg`` (degrees), ``max_clipped_share`` (share of the face),
        ``max_noise_mm`` (mm).

    Returns
    -------
    list of Warning
        The takes left out of the subject first, then in stage order, then take order.
    """
    out: list[Warning] = [
        Warning(f.stage, t, f"left out of the subject: {f.reason}")
        for t, f in read_failures(h5).items()
    ]
    takes = h5.get(paths.TAKES, {})
    data = _ReadOnce(h5)
    for take in takes:
        valid = h5.get(paths.mesh(take, "valid"))
        if valid is not None and valid[()].mean() < settings["min_valid_fraction"]:
            share = 100 * valid[()].mean()
            out.append(Warning("fit", take, f"only {share:.0f}% of the template has data"))
        if bool(takes[take].attrs.get("grey_color", False)):
            out.append(Warning("ingest", take, GREY))
        if (share := take_clipped_share(data, take)) and share > float(
            settings["max_clipped_share"]
        ):
            said = CLIPPED.format(share=100 * share, example=CLIPPED_EXAMPLE)
            out.append(Warning("ingest", take, said))
        folded = int(takes[take].attrs.get("n_folded", 0))
        if folded:
            out.append(Warning("fit", take, f"{folded} folded triangles in the fitted template"))
        if len(off := unmeasured_landmarks(data, take)) > MAX_UNMEASURED_POINTS:
            out.append(Warning("fit", take, UNMEASURED.format(n=len(off), points=_ranges(off))))
    for take in takes:
        if bool(h5.get(paths.align(take, "ok"), True)[()]):
            continue
        problems = json.loads(h5[paths.align_group(take)].attrs.get("problems", "[]")) or [
            "the alignment failed its quality gate"
        ]
        if problems:
            fate = (
                "kept in the models (quality.include_failed_takes)"
                if settings["include_failed_takes"]
                else "left out of the models"
            )
            out.append(Warning("align", take, f"{'; '.join(problems)}: {fate}"))
    sources = {t: landmark_source(h5, t) for t in takes}
    given = [t for t, source in sources.items() if source.startswith("clicked")]
    neutral = next((t for t in takes if str(takes[t].attrs.get("kind", "")) == "neutral"), "")
    out += _turned_warnings(h5, data, list(takes), neutral, settings)
    out += _noise_warnings(h5, list(takes), neutral, settings)
    for take in takes:
        doubtful = h5.get(paths.landmark_info(take, "doubtful"))
        if doubtful is not None and doubtful.asstr()[()]:
            others = [t for t in given if t != take]
            said = doubtful.asstr()[()] + _what_it_does(h5, take, neutral, others)
            out.append(Warning("landmarks", take, said))
    for take in takes:
        group = h5.get(paths.refine_group(take))
        problem = group.attrs.get("problem", "") if group is not None else ""
        if problem:
            out.append(Warning("refine", take, str(problem)))
    if shaped := [t for t in takes if _shape_refined(h5, t)]:
        out.append(Warning("refine", "", SHAPE_REFINED.format(takes=", ".join(shaped))))
    detected = any("detected" in source for source in sources.values())
    out += _motion_noise_warnings(h5, settings, detected)
    return out


#: The warning of a take seen from another direction than its neutral (:func:`_turned_warnings`).
TURNED = (
    "seen from {turn:.0f} degrees away from where its neutral was seen (the head turned between "
    "them): the side of the face it sees more obliquely than the neutral is matched less well "
    "(the real head's smile with its landmark files: {example}); scan every take from the "
    "neutral's direction"
)
#: :data:`TURNED`'s measured example (``benchmarks/bench_turned_takes.py``, seed 7).
TURNED_EXAMPLE = (
    "0.12 of its motion in error seen as the neutral is, 0.26 turned 15 degrees, 0.41 turned 20, "
    "1.31 turned 30"
)


def take_clipped_share(data: Mapping, take: str) -> float:
    """:func:`~scan2morph.refine.clipped_share` of a take's stored colour image over its face
    (the pixels with a surface point within its landmarks' hull); 0 without a colour image or
    fewer than three landmarks."""
    keys = [paths.range_image(take, "color"), paths.range_image(take, "xyz"), paths.landmarks(take)]
    if any(k not in data for k in keys):
        return 0.0
    color, xyz, points = (data[k] for k in keys)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) < 3:
        return 0.0
    return clipped_share(color, face_region(finite_points(xyz), points))


class _ReadOnce(Mapping):
    """A store's datasets, each read once: the gates read a take's range image for several
    checks, and the neutral's for every take's turn."""

    def __init__(self, h5: h5py.File):
        self.h5, self.read = h5, {}

    def __getitem__(self, key: str) -> np.ndarray:
        if key not in self.read:
            self.read[key] = self.h5[key][()]
        return self.read[key]

    def __contains__(self, key) -> bool:
        return key in self.h5

    def __iter__(self):
        return iter(self.h5)

    def __len__(self) -> int:
        return len(self.h5)


def _noise_warnings(
    h5: h5py.File, takes: list[str], neutral: str, settings: Mapping
) -> list[Warning]:
    """A warning for each take, the neutral among them, whose surface the alignment measured
    noisier than ``settings["max_noise_mm"]`` mm (the align group's ``noise_take_mm``, and
    ``noise_neutral_mm`` of the first aligned take for the neutral)."""
    noise = {}
    for take in takes:
        group = h5.get(paths.align_group(take))
        if group is None or "noise_take_mm" not in group.attrs:
            continue
        noise[take] = float(group.attrs["noise_take_mm"])
        noise.setdefault(neutral, float(group.attrs.get("noise_neutral_mm", np.nan)))
    if not noise:
        return []
    limit = float(settings["max_noise_mm"])
    said = {t: n for t, n in noise.items() if t and n > limit}
    return [
        Warning("align", t, NOISY.format(noise=said[t], example=NOISY_EXAMPLE))
        for t in takes
        if t in said
    ]


def _turned_warnings(
    h5: h5py.File, data: Mapping, takes: list[str], neutral: str, settings: Mapping
) -> list[Warning]:
    """A warning for each take seen from more than ``settings["max_view_turn_deg"]`` degrees
    away from where its neutral was (:func:`~scan2morph.stages.take_mesh.view_turn` of the
    store's datasets ``data``, each read once); not for a take whose alignment failed its gate
    (its turn would be the failed alignment's)."""
    out = []
    for take in takes:
        if take == neutral or not neutral or paths.align(take, "transform") not in h5:
            continue
        if not bool(h5.get(paths.align(take, "ok"), True)[()]):
            continue
        turn = view_turn(data, (take, neutral), take)
        if turn > float(settings["max_view_turn_deg"]):
            out.append(Warning("align", take, TURNED.format(turn=turn, example=TURNED_EXAMPLE)))
    return out


#: The eye, nose and mouth points (iBUG 28-68): the brows (18-27) often lie on hair a scanner
#: does not see, the jawline on the face's outline.
INNER_FACE = range(27, 68)
#: More of those points on no data than this is a warning (:func:`unmeasured_landmarks`): the
#: default cohort's takes have 0-3 (the inner lips over an open mouth); a scan cut below the
#: nose, 38 of the 68.
MAX_UNMEASURED_POINTS = 8
UNMEASURED = (
    "{n} of its 41 eye, nose and mouth landmarks (iBUG {points}) lie where its scan has no data: "
    "the template there is filled in from the measured skin around it, not measured"
)


def unmeasured_landmarks(h5: h5py.File | Mapping, take: str) -> list[int]:
    """The take's eye, nose and mouth landmarks (iBUG numbers, :data:`INNER_FACE`) with no range
    data within a pixel of them (or outside its image); empty without landmarks or a range
    image."""
    from scipy import ndimage

    points, xyz = h5.get(paths.landmarks(take)), h5.get(paths.range_image(take, "xyz"))
    if points is None or xyz is None:
        return []
    has = ndimage.binary_dilation(np.isfinite(xyz[()]).all(axis=2))
    p = np.asarray(points[()], dtype=np.float64)[list(INNER_FACE)]
    ok = np.isfinite(p).all(axis=1)
    r = np.rint(np.where(ok, p[:, 1], -1)).astype(int)
    c = np.rint(np.where(ok, p[:, 0], -1)).astype(int)
    inside = ok & (r >= 0) & (r < has.shape[0]) & (c >= 0) & (c < has.shape[1])
    seen = np.zeros(len(p), dtype=bool)
    seen[inside] = has[r[inside], c[inside]]
    return [int(i) + 1 for i, s in zip(INNER_FACE, seen, strict=True) if not s]


def _ranges(numbers: list[int]) -> str:
    """``[28, 29, 30, 49]`` as ``28-30, 49``."""
    runs: list[list[int]] = []
    for n in numbers:
        if runs and n == runs[-1][-1] + 1:
            runs[-1].append(n)
        else:
            runs.append([n])
    return ", ".join(f"{r[0]}-{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in runs)


def _shape_refined(h5: h5py.File, take: str) -> bool:
    """The take's texture did not correlate with the neutral's: its shape refined it."""
    group = h5.get(paths.refine_group(take))
    return group is not None and bool(group.attrs.get("shape_used", False))


def _what_it_does(h5: h5py.File, take: str, neutral: str, given: list[str]) -> str:
    """What a doubtful detection's error does to the model, for the report's warning: the
    neutral's points place the template on the face; another take's error is taken up where its
    refinement followed the skin from the neutral (by the skin's texture, or by the surface's
    shape where the refinement said so), and for a take the takes' consensus moved, where that
    consensus did, with its own numbers (``""`` when neither ran). When the subject mixes
    detected and given landmarks (``given``: the other takes whose landmarks were given;
    ``neutral``: the subject's neutral take), the
    detection's error is not shared by theirs: it is in the motion between them, and it says
    so (a clicked take beside a detected neutral moved 25 times the error of both detected on
    the real head). A detected take whose neutral's landmarks were given follows them through
    the skin where the texture correlates (:func:`scan2morph.stages.landmarks.second_pass`),
    and it says that instead."""
    tracked = "landmarks_tracked" in h5[paths.TAKES][take].attrs  # its second pass tracked
    if tracked and neutral in given:
        return (
            "; its neutral's landmarks were given: where the skin's texture correlates its "
            "points follow the neutral's, elsewhere this detection's error is in its motion "
            "(give this take's landmarks too, or none for any take)" + _taken_up(h5, take)
        )
    if given:
        return (
            f"; the subject mixes detected and given landmarks (given: {', '.join(given)}): this "
            "detection's error is not in theirs, so it is in the motion between them where no "
            "refinement follows the skin; give this take's landmarks too, or none for any take"
            + ("" if take == neutral else _taken_up(h5, take))
        )
    if take == neutral:
        return (
            "; the neutral's points place the template on the face: their error moves which "
            "skin each vertex is (a mouth-corner vertex off the corner), not the takes' motions"
        )
    return _taken_up(h5, take)


def _taken_up(h5: h5py.File, take: str) -> str:
    """Where a take's refinement or the takes' consensus took up its detection error."""
    group = h5.get(paths.refine_group(take))
    refine = group.attrs if group is not None else {}
    consensus = h5.get(paths.consensus_group(take))
    if consensus is not None and "confident_share" in consensus.attrs:
        attrs, what = consensus.attrs, "the takes' consensus (their shared texture)"
    elif bool(refine.get("used", False)):
        by = "the surface's shape" if bool(refine.get("shape_used", False)) else "its texture"
        attrs, what = refine, f"its refinement (by {by})"
    else:
        return ""
    share = float(attrs.get("confident_share", np.nan))
    moved = float(attrs.get("median_correction_px", np.nan))
    if not (np.isfinite(share) and np.isfinite(moved)):
        return ""
    return (
        f"; {what} measured where its skin went on {share:.0%} of the face, a median "
        f"{moved:.1f} px from the landmarks' fit: there the take's own detection error is taken "
        "up"
    )


def _motion_noise_warnings(h5: h5py.File, settings: Mapping, detected: bool) -> list[Warning]:
    """The error bar's warnings: takes whose refits were refused, a scatter above the limit
    (``detected``: some takes' landmarks were detected, so it is not the clicks')."""
    out = []
    if paths.motion_noise("failed_draws") in h5:
        names = h5[paths.motion_noise("takes")].asstr()[()]
        failed = h5[paths.motion_noise("failed_draws")][()]
        draws = int(h5[paths.MOTION_NOISE].attrs.get("draws", 0))
        for take, n in zip(names, failed, strict=True):
            if not n:
                continue
            message = (
                f"too few of its {draws} click-noise refits fitted (or of its neutral's: the "
                "click noise is too large for the template; the motion_noise log says why): it "
                "has no error bar"
                if draws and n >= draws
                else f"{int(n)} of {draws} click-noise refits refused: its error bar is partial"
            )
            out.append(Warning("motion_noise", str(take), message))
    key = paths.motion_noise("click_noise_measured_px")
    if key in h5:
        measured = float(h5[key][()])
        limit = float(settings["max_click_noise_px"])
        if np.isfinite(measured) and measured > limit:
            message = (
                f"the landmark {'points' if detected else 'clicks'} scatter by {measured:.2f} px, "
                f"above {limit:g} px: the motion of small visemes is not to be trusted"
            )
            out.append(Warning("motion_noise", "", message))
    return out


__all__ = [
    "Warning",
    "aligned_takes",
    "modelled",
    "read_warnings",
    "skipped_stages",
    "subject_warnings",
    "take_clipped_share",
    "warning_datasets",
]
