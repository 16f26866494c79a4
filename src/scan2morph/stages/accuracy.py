"""Accuracy: a synthetic subject's outputs against its ground truth (mm, degrees, fractions)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from scan2morph.evaluate.landmarks import landmark_summary, take_landmarks
from scan2morph.evaluate.subject import IdealMotion, subject_accuracy
from scan2morph.evaluate.truth import Truth
from scan2morph.stages import fit as fit_stage
from scan2morph.stages.failure import failures, usable
from scan2morph.stages.part import Part, Subject
from scan2morph.stages.quality import modelled, read_warnings
from scan2morph.template import Template

#: Config sections this stage reads (the fit's and the smoothing's, for the ideal motion).
SECTIONS = ("template", "smoothing")
#: The group of each take's ground truth in the stage's data (:func:`truth_datasets`).
TRUTH = "/truth"


@dataclass(frozen=True)
class Params:
    """Accuracy parameters.

    Attributes
    ----------
    fit : scan2morph.stages.fit.Params
        The fit's (fiducial sets, levels, the depth-step rule), for the ideal correspondence.
    smoothing : mapping
        The config section ``smoothing``, for the ideal motion.
    """

    fit: fit_stage.Params
    smoothing: Mapping

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``template`` and ``smoothing``."""
        return cls(fit_stage.Params.from_config(config), dict(config["smoothing"]))


def truth_datasets(truths: Mapping[str, Truth]) -> dict[str, np.ndarray]:
    """Each take's ground truth as datasets ``/truth/{take}/{key}`` (the keys of a truth file,
    :mod:`scan2morph.evaluate.truth`), beside the store's in the stage's data."""
    out = {}
    for take, truth in truths.items():
        arrays = {f.name: getattr(truth, f.name) for f in fields(truth) if f.name != "extra"}
        out |= {f"{TRUTH}/{take}/{k}": v for k, v in (arrays | truth.extra).items()}
    return out


def _truths(data: Mapping[str, np.ndarray], takes) -> dict[str, Truth]:
    """The takes' ground truth held in ``data`` (:func:`truth_datasets`)."""
    out = {}
    for take in takes:
        prefix = f"{TRUTH}/{take}/"
        arrays = {k.removeprefix(prefix): v for k, v in data.items() if k.startswith(prefix)}
        if arrays:
            out[take] = Truth.from_arrays(arrays, source=f"{TRUTH}/{take}")
    return out


def run(
    template: Template, subject: Subject, data: Mapping[str, np.ndarray], params: Params
) -> Part:
    """``accuracy.json`` of one subject.

    Parameters
    ----------
    template : Template
        The base template.
    subject : Subject
    data : mapping path -> array
        The subject's store (or the same datasets held in memory by a sweep) and each take's
        ground truth (:func:`truth_datasets`).
    params : Params

    Returns
    -------
    Part
        No datasets; ``files["accuracy"]`` is
        :func:`scan2morph.evaluate.subject.subject_accuracy`'s report, with the store's
        ``warnings`` (one line each; a take left out of the models has no motion entry) and
        ``failed_takes`` (take -> ``stage`` and ``reason``: the takes left out of the subject,
        :mod:`scan2morph.stages.failure`, measured nowhere else); each take's ``landmarks``
        against the truth (:func:`~scan2morph.evaluate.landmarks.take_landmarks`).
    """
    store = {k: v for k, v in data.items() if not k.startswith(f"{TRUTH}/")}
    left_out = failures(store)
    subject = usable(subject, store)
    truths = _truths(data, subject.kinds)
    fit = params.fit
    ideal = IdealMotion(
        template,
        {t: fit.fiducial_set(k) for t, k in subject.kinds.items()},
        fit.rules.levels,
        params.smoothing,
        fit.rules.max_slope_deg,
    )
    kept = modelled(subject, store)
    report = subject_accuracy(
        store, truths, subject.neutral, kept.visemes, ideal, expressions=kept.expressions
    )
    errors = take_landmarks(store, truths)
    for t, entry in errors.items():
        report["takes"][t]["landmarks"] = entry
    report["summary"] |= landmark_summary(errors)
    report |= {
        "warnings": [str(w) for w in read_warnings(store)],
        "failed_takes": {t: {"stage": f.stage, "reason": f.reason} for t, f in left_out.items()},
    }
    return Part(files={"accuracy": report})
