"""A subject's warnings and skipped stages as the store holds them: the record and its readers.

The quality gates that produce the warnings are :mod:`scan2morph.stages.quality`'s; this module
is what the report, the model API and the gates share, low in the data flow.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import h5py
import numpy as np

from scan2morph.store import paths


@dataclass(frozen=True)
class Warning:
    """One problem of one subject.

    Attributes
    ----------
    stage : str
        The stage that found it (``align``, ``fit``, ``motion_noise``, ...).
    take : str
        The take it concerns (empty: the whole subject).
    message : str
        What went wrong and what was done about it, in one line.
    """

    stage: str
    take: str
    message: str

    def __str__(self) -> str:
        where = f"{self.take}: " if self.take else ""
        return f"[{self.stage}] {where}{self.message}"


@dataclass(frozen=True)
class Failure:
    """Why a take was left out of its subject (``/failed/{take}``; written by
    :mod:`scan2morph.stages.failure`).

    Attributes
    ----------
    take : str
        The take id.
    stage : str
        The per-take stage that refused it (``ingest``, ``repair``, ``fit``, ``align``, ``refine``).
    reason : str
        The stage's one-line message.
    """

    take: str
    stage: str
    reason: str

    def datasets(self) -> dict[str, str]:
        """The record at its store paths."""
        return {
            paths.failed(self.take, "stage"): self.stage,
            paths.failed(self.take, "reason"): self.reason,
        }

    def __str__(self) -> str:
        return f"{self.take} left out at {self.stage}: {self.reason}"


def read_failures(data) -> dict[str, Failure]:
    """The takes left out of a subject (``/failed``), take -> :class:`Failure`.

    Parameters
    ----------
    data : h5py.File or mapping store path -> array
        A store or part opened with h5py, or datasets read from parts or a store.
    """
    if isinstance(data, h5py.Group):
        takes = list(data.get(paths.FAILED, {}))
    else:
        takes = paths.ids(data, paths.FAILED, "reason")
    return {
        t: Failure(t, *(text_value(data[paths.failed(t, f)]) for f in ("stage", "reason")))
        for t in takes
    }


def warning_datasets(warnings: list[Warning]) -> dict[str, np.ndarray]:
    """The ``/warnings`` group of the store: ``stage``, ``take`` and ``message``, one per warning."""
    return {
        paths.warnings(field): np.asarray([getattr(w, field) for w in warnings], dtype=object)
        for field in ("stage", "take", "message")
    }


def read_warnings(data: Mapping[str, np.ndarray]) -> list[Warning]:
    """The warnings of a store (an open h5py file, or a mapping from
    :func:`scan2morph.store.read_part`); none for a store written before format 1.2."""
    if paths.warnings("message") not in data:
        return []
    cols = [_text(data[paths.warnings(f)]) for f in ("stage", "take", "message")]
    return [Warning(str(s), str(t), str(m)) for s, t, m in zip(*cols, strict=True)]


def _text(value) -> list[str]:
    if hasattr(value, "asstr"):  # an h5py dataset
        value = value.asstr()[()]
    return [str(v) for v in np.asarray(value, dtype=object).tolist()]


def text_value(value) -> str:
    """A string dataset's text, whether an h5py dataset, bytes or str (as :func:`read_part`
    gives it)."""
    if hasattr(value, "asstr"):  # an h5py dataset
        value = value.asstr()[()]
    return value.decode() if isinstance(value, bytes) else str(value)


def landmark_source(store: Mapping, take: str) -> str:
    """How a take's landmarks were found (``landmark_source``): ``clicked``, ``detected`` or
    ``clicked+detected jawline``; ``clicked`` for a store from before the landmarks stage.
    ``store``: an open store, a part's datasets or a merged mapping of them."""
    value = store.get(paths.landmark_info(take, "source"))
    if value is None:
        return "clicked"
    return text_value(value.item() if isinstance(value, np.ndarray) else value)


def skipped_stages(h5: h5py.File) -> dict[str, str]:
    """Stages (or parts of them) a subject skipped: name -> why."""
    group = h5.get(paths.SKIPPED)
    if group is None:
        return {}
    return {k: (v.decode() if isinstance(v, bytes) else str(v)) for k, v in group.attrs.items()}
