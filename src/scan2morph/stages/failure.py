"""Take isolation: a take that fails leaves its subject, the subject is built from the rest.

A per-take stage (ingest, repair, fit, align, refine) that refuses its take (bad input, a quality
gate: an :class:`~scan2morph.errors.InputError`) does not fail its job. It writes a *failure
record* instead of its part: ``/failed/{take}/stage`` and ``/failed/{take}/reason``. Every later
per-take stage of that take finds the record among its inputs and hands it on unchanged, so the
subject-level stages see it in whatever parts they read. They drop the take (:func:`usable`);
the store keeps the record and none of the take's other data, the report puts the reason at its
top, ``accuracy.json`` lists it and the cohort summary names the takes left out.

Only the neutral is needed by every other take: a failed neutral stops its subject (one line
naming the neutral and why), never another subject.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

import h5py
import numpy as np

from scan2morph.errors import InputError, OutputError
from scan2morph.jobs import run_job
from scan2morph.stages.part import Subject
from scan2morph.store import write_part
from scan2morph.store.warnings import Failure
from scan2morph.store.warnings import read_failures as failures

log = logging.getLogger("scan2morph")


def part_failures(parts: Iterable[str | Path]) -> dict[str, Failure]:
    """The failure records in part files (read without loading their other datasets)."""
    out: dict[str, Failure] = {}
    for part in parts:
        with h5py.File(part, "r") as h5:
            out |= failures(h5)
    return out


def usable(subject: Subject, data: Mapping[str, np.ndarray]) -> Subject:
    """The subject without its failed takes.

    Parameters
    ----------
    subject : Subject
    data : mapping store path -> array
        Datasets of the parts (or the store) the stage reads; failure records included.

    Raises
    ------
    InputError
        The neutral failed: the subject cannot be built (one line naming it and why).
    """
    failed = failures(data)
    neutral = subject.neutral
    if neutral in failed:
        record = failed[neutral]
        raise InputError(
            subject.name,
            f"the neutral take {neutral} was refused at {record.stage} ({record.reason}); "
            "every other take is measured against it, so the subject is not built",
        )
    return subject.keep([t for t in subject.kinds if t != neutral and t not in failed])


def run_take_job(
    log_path: str | Path | None,
    job: Callable[[], object],
    *,
    take: str,
    stage: str,
    inputs: Iterable[str | Path],
    part: str | Path,
    on_failure: Callable[[Failure, InputError | None], None] | None = None,
) -> None:
    """Run a per-take stage's job with take isolation (see the module docstring).

    Parameters
    ----------
    log_path : str or Path or None
        The job's log file (:func:`scan2morph.jobs.run_job`).
    job : callable
        Reads the inputs, runs the stage and writes every output.
    take, stage : str
        The take and the stage (for the record).
    inputs : iterable of paths
        The job's input parts: a failure record in any of them is handed on without running
        ``job`` (the neutral's record too: a take cannot be aligned to a neutral that failed).
    part : str or Path
        The job's part, written as the failure record when the take fails.
    on_failure : callable, optional
        ``on_failure(record, error)`` writes the job's other outputs for a failed take (e.g.
        the fit's OBJ saying why); ``error`` is the stage's refusal (None for a record handed
        on), which may carry what the user can mend (a refused detection's points).

    Notes
    -----
    A full disk (:class:`~scan2morph.errors.OutputError`) and any error that is not bad input
    still fail the job: they are the run's problem, not the take's.
    """

    def isolated():
        inherited, error = part_failures(inputs), None
        if inherited:
            record = inherited.get(take) or next(iter(inherited.values()))
            log.info("%s: not run, %s", take, record)
        else:
            try:
                job()
                return
            except OutputError:
                raise
            except InputError as exc:
                record, error = Failure(take, stage, str(exc)), exc
                log.warning("%s is left out of its subject: %s", take, exc)
        write_part(part, record.datasets())
        if on_failure is not None:
            on_failure(record, error)

    run_job(log_path, isolated)


__all__ = ["Failure", "failures", "part_failures", "run_take_job", "usable"]
