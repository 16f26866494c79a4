"""Errors raised on bad input.

Every error that a user's data can trigger is an :class:`InputError`: its message names the
source (a file, or a subject/take), the field and what was expected, so that a failed job's log
tells the user what to fix without a traceback hunt.
"""

from __future__ import annotations

import errno
import numbers
import shutil
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from os import PathLike
from pathlib import Path
from typing import Any


class InputError(ValueError):
    """Bad input data: names the source, the field and what was expected.

    Parameters
    ----------
    source : str or path-like
        The file, or a ``subject/take`` label, the problem was found in.
    problem : str
        What is wrong and what was expected, e.g. ``"n_points: expected 68, got 67"``.
    """

    def __init__(self, source: str | PathLike[str], problem: str):
        self.source = str(source)
        self.problem = problem
        super().__init__(f"{self.source}: {problem}")


def require_numbers(source: str | PathLike[str], values: Mapping[str, Any]) -> None:
    """Raise an :class:`InputError` for the first value that is not a real number.

    Parameters
    ----------
    source : str or path-like
        Where the values come from (e.g. ``"config"``).
    values : mapping field name -> value
        The field names go into the message (e.g. ``"start"``); booleans are not
        numbers here.
    """
    for name, value in values.items():
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise InputError(source, f"{name}: expected a number, got {value!r}")


#: ``errno`` values of a full disk (or a used-up quota).
_DISK_FULL = (errno.ENOSPC, errno.EDQUOT)


class OutputError(InputError):
    """An output file could not be written because the disk is full: one line naming the file.

    A subclass of :class:`InputError` so that a job reports it as one line without a traceback
    (:func:`scan2morph.jobs.run_job`); ``str(exc)`` is ``no space left on device writing <file>``.
    """

    def __init__(self, path: str | PathLike[str]):
        super().__init__(path, f"no space left on device writing {path}")
        self.args = (f"no space left on device writing {path}",)

    def __str__(self) -> str:
        return self.args[0]


def disk_full(exc: BaseException) -> bool:
    """True when ``exc`` is an ``OSError`` of a full disk (ENOSPC / EDQUOT, also as h5py and
    other libraries word it in the message)."""
    if not isinstance(exc, OSError):
        return False
    return exc.errno in _DISK_FULL or "no space left on device" in str(exc).lower()


@contextmanager
def writing(path: str | PathLike[str]) -> Iterator[None]:
    """Turn a full-disk ``OSError`` raised while writing ``path`` into :class:`OutputError`."""
    try:
        yield
    except OSError as exc:
        if disk_full(exc):
            raise OutputError(path) from None
        raise


def no_space_left(path: str | PathLike[str], needed: int = 1) -> bool:
    """True when the folder of ``path`` has fewer than ``needed`` bytes free (for writers, such
    as OpenCV's, that report a failed write without the reason)."""
    try:
        return shutil.disk_usage(Path(path).resolve().parent).free < needed
    except OSError:
        return False


__all__ = ["InputError", "OutputError", "disk_full", "no_space_left", "writing"]
