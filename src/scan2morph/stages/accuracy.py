"""Accuracy: a synthetic subject's outputs against its ground truth (mm, degrees, fractions)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scan2morph.evaluate.landmarks import landmark_summary, take_landmarks
from scan2morph.evaluate.subject import subject_accuracy
from scan2morph.evaluate.truth import Truth
from scan2morph.stages.failure import failures, usable
from scan2morph.stages.fit import fiducial_set
from scan2morph.stages.part import Subject
from scan2morph.stages.quality import modelled, read_warnings
from scan2morph.store import paths
from scan2morph.template import Template

#: Config sections this stage reads (the fit's and the smoothing's, for the ideal motion).
SECTIONS = ("template", "smoothing")


def run(
    template: Template,
    subject: Subject,
    store: Mapping[str, np.ndarray],
    truths: Mapping[str, Truth],
    config: Mapping,
) -> dict:
    """``accuracy.json`` of one subject.

    Parameters
    ----------
    template : Template
        The base template.
    subject : Subject
    store : mapping store path -> array
        The subject's store (or the same datasets held in memory by a sweep).
    truths : mapping take -> Truth
    config : mapping section -> mapping
        The sections ``template`` and ``smoothing``.

    Returns
    -------
    dict
        :func:`scan2morph.evaluate.subject.subject_accuracy`'s report, with the store's
        ``warnings`` (one line each; a take left out of the models has no motion entry) and
        ``failed_takes`` (take -> ``stage`` and ``reason``: the takes left out of the subject,
        :mod:`scan2morph.stages.failure`, measured nowhere else); each take's ``landmarks``
        against the truth (:func:`~scan2morph.evaluate.landmarks.take_landmarks`).
    """
    section = config["template"]
    left_out = failures(store)
    subject = usable(subject, store)
    truths = {t: truth for t, truth in truths.items() if t in subject.kinds}
    report = subject_accuracy(
        store,
        truths,
        subject.neutral,
        (kept := modelled(subject, store)).visemes,
        template=template,
        fiducial_sets={t: fiducial_set(section, k) for t, k in subject.kinds.items()},
        levels=int(section["subdivision_levels"]),
        smoothing=config["smoothing"],
        max_slope_deg=section["max_slope_deg"],
        expressions=kept.expressions,
    )
    sources = {
        t: _text(store[paths.landmark_info(t, "source")])
        for t in truths
        if paths.landmark_info(t, "source") in store
    }
    errors = take_landmarks(store, truths, sources)
    for t, entry in errors.items():
        report["takes"][t]["landmarks"] = entry
    report["summary"] |= landmark_summary(errors)
    return report | {
        "warnings": [str(w) for w in read_warnings(store)],
        "failed_takes": {t: {"stage": f.stage, "reason": f.reason} for t, f in left_out.items()},
    }


def _text(value) -> str:
    """A string dataset as read from a part or store (bytes or str)."""
    value = value.item() if hasattr(value, "item") else value
    return value.decode() if isinstance(value, bytes) else str(value)
