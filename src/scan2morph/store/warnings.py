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


def skipped_stages(h5: h5py.File) -> dict[str, str]:
    """Stages (or parts of them) a subject skipped: name -> why."""
    group = h5.get(paths.SKIPPED)
    if group is None:
        return {}
    return {k: (v.decode() if isinstance(v, bytes) else str(v)) for k, v in group.attrs.items()}
