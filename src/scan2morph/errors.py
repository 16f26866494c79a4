"""Errors raised on bad input.

Every error that a user's data can trigger is an :class:`InputError`: its message names the
source (a file, or a subject/take), the field and what was expected, so that a failed job's log
tells the user what to fix without a traceback hunt.
"""

from __future__ import annotations

from os import PathLike


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


__all__ = ["InputError"]
