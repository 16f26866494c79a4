"""Store: merge a subject's parts into its versioned HDF5 file, add its warnings, check it."""

from __future__ import annotations

import io
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import h5py

from scan2morph.errors import InputError
from scan2morph.jobs import config_sha256
from scan2morph.provenance import run_provenance
from scan2morph.stages.failure import part_failures
from scan2morph.stages.part import Part, Subject
from scan2morph.stages.quality import subject_warnings, warning_datasets
from scan2morph.stages.stage_job import code_fingerprints
from scan2morph.store import paths, validate_store
from scan2morph.store.hdf5 import merge_into, write_into
from scan2morph.store.layout import describe
from scan2morph.template import Template

#: Config section this stage reads.
SECTIONS = ("quality",)
#: The config's top-level keys that never reach a store: the report page's settings, the sweep
#: table's path and the sheet's path (a take's rows and files reach it as the take's own inputs;
#: left out of the store's ``config_sha256``, so that changing them, or moving the sheet, does
#: not rebuild the store and every stage after it).
UNSTORED = ("report", "sweeps", "subjects")
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Store parameters.

    Attributes
    ----------
    quality : mapping
        The config section ``quality`` (:func:`scan2morph.stages.quality.subject_warnings`).
    config_sha256 : str
        The run's config hash without :data:`UNSTORED` (:func:`scan2morph.jobs.config_sha256`),
        a root attribute.
    layout : mapping
        ``schemas/store.layout.yaml``, loaded (:meth:`with_layout`): the store is described and
        checked by it.
    """

    quality: Mapping
    config_sha256: str
    layout: Mapping = field(default_factory=dict)

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's section ``quality`` and the config's hash without :data:`UNSTORED`
        (no layout yet)."""
        return cls(dict(config["quality"]), config_sha256(config, UNSTORED))

    def with_layout(self, layout: Mapping) -> Params:
        """The same parameters with the store layout."""
        return replace(self, layout=layout)


def run(
    template: Template | None, subject: Subject, data: Mapping[str, Sequence], params: Params
) -> Part:
    """``results/{subject}/{subject}.h5``, built in memory.

    Parameters
    ----------
    template : Template or None
        Not used (the contract's shape).
    subject : Subject
        Its ``name`` (a root attribute).
    data : mapping
        ``parts``: the paths of every stage part of the subject (the store merges their files,
        attributes and failure records, not only their datasets). A take left out of its
        subject (a failure record in its parts, :mod:`scan2morph.stages.failure`) keeps only
        that record in the store. ``code_sha256`` (optional): the code fingerprint of the
        stages that made the parts (the workflow's, computed once a run), else computed here
        (:func:`scan2morph.stages.stage_job.code_fingerprints`); a root attribute with the
        git commit and the dependencies' versions (:func:`scan2morph.provenance.run_provenance`).
    params : Params

    Returns
    -------
    Part
        No datasets; ``files["store"]`` is the store's bytes (for
        :func:`scan2morph.store.hdf5.write_file`) and ``files["warnings"]`` the subject's
        warnings (also written to ``/warnings`` and logged).

    Raises
    ------
    InputError
        Two parts writing one dataset, or a store that does not match the layout.
    """
    parts = list(data["parts"])
    failed = part_failures(parts)
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as h5:
        exclude = [paths.take(t) for t in failed]
        merge_into(h5, parts, subject.name, params.config_sha256, exclude, _provenance(data))
        warnings = subject_warnings(h5, params.quality)
        write_into(h5, warning_datasets(warnings))
        describe(h5, dict(params.layout))
    for warning in warnings:
        # a take left out: its own job said so, and the run's last lines say it again
        left_out = warning.take in failed and warning.stage == failed[warning.take].stage
        (log.info if left_out else log.warning)("%s: %s", subject.name, warning)
    problems = validate_store(io.BytesIO(buffer.getvalue()), dict(params.layout))
    if problems:
        raise InputError(
            f"{subject.name} store",
            "does not match schemas/store.layout.yaml: " + "; ".join(problems),
        )
    return Part(files={"store": buffer.getvalue(), "warnings": warnings})


def _provenance(data: Mapping) -> dict[str, object]:
    """The root attributes that say which code made the store."""
    code = data.get("code_sha256") or code_fingerprints(["store"])["store"]
    return run_provenance(code)
