"""Store: merge a subject's parts into its versioned HDF5 file, add its warnings, check it."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from pathlib import Path

from scan2morph.errors import InputError
from scan2morph.stages.failure import part_failures
from scan2morph.stages.quality import subject_warnings, warning_datasets
from scan2morph.store import paths, validate_store
from scan2morph.store.hdf5 import hdf5_output, merge_into, write_into
from scan2morph.store.layout import describe

#: Config section this stage reads.
SECTIONS = ("quality",)
log = logging.getLogger("scan2morph")


def run(
    path: str | Path,
    parts: Iterable[str | Path],
    subject: str,
    config_sha256: str,
    quality: Mapping,
    layout: dict,
) -> list:
    """Write ``results/{subject}/{subject}.h5``.

    Parameters
    ----------
    path : str or Path
        The store (replaced).
    parts : iterable of paths
        Every stage part of the subject. A take left out of its subject (a failure record in
        its parts, :mod:`scan2morph.stages.failure`) keeps only that record in the store.
    subject, config_sha256 : str
        Root attributes.
    quality : mapping
        The config section ``quality`` (:func:`scan2morph.stages.quality.subject_warnings`).
    layout : dict
        ``schemas/store.layout.yaml``, loaded.

    Returns
    -------
    list of Warning
        The subject's warnings, also written to ``/warnings`` and logged.

    Raises
    ------
    InputError
        Two parts writing one dataset, or a store that does not match the layout.
    """
    parts = list(parts)
    failed = part_failures(parts)
    with hdf5_output(path) as h5:  # built in memory, written once
        merge_into(h5, parts, subject, config_sha256, exclude=[paths.take(t) for t in failed])
        warnings = subject_warnings(h5, quality)
        write_into(h5, warning_datasets(warnings))
        describe(h5, layout)
    for warning in warnings:
        log.warning("%s: %s", subject, warning)
    problems = validate_store(path, layout)
    if problems:
        raise InputError(path, "does not match schemas/store.layout.yaml: " + "; ".join(problems))
    return warnings
