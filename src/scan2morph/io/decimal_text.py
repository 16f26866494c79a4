"""Plain decimal numbers in text, parsed a whole line at a time and exactly as Python reads them.

An FRGC ``.abs`` range image holds its 640 x 480 pixels as four text lines of 307,200 numbers
each (``-21.123456``). Converting each token with ``float`` (``np.array(line.split(), float)``)
took 0.43 s of a take's 0.45 s ingest. :func:`parse_decimals` reads a line of *plain* decimals
(an optional ``-``, digits, at most one ``.``; 15 digits at the most) with whole-array
operations instead: each token's digits make an integer ``N`` (exact in float64, below
``2**53``) and its ``k`` digits after the point a power of ten ``10**k`` (exact for ``k <= 22``),
and the IEEE division ``N / 10**k`` rounds the exact quotient once, correctly: the same float64,
bit for bit, as ``float(token)``, which rounds the same decimal value correctly. A line with
anything else (an exponent, ``nan``, a ``+``, a tab, more digits) is not read here: the caller
reads it token by token, as before, with its error messages.
"""

from __future__ import annotations

import numpy as np

#: Most digits of a token read here: ``10**15 < 2**53``, so its digits are an exact float64.
MAX_DIGITS = 15
_SPACE, _MINUS, _DOT, _ZERO = 32, 45, 46, 48
#: Bytes a line read here may hold: space, ``-``, ``.`` and the digits.
_PLAIN = np.zeros(256, dtype=bool)
_PLAIN[[_SPACE, _MINUS, _DOT]] = True
_PLAIN[_ZERO : _ZERO + 10] = True
#: Exact powers of ten, 10**0 to 10**MAX_DIGITS.
_POW10 = 10.0 ** np.arange(MAX_DIGITS + 1)


def _tokens(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) byte offsets of the space-separated tokens of ``c``."""
    word = np.empty(len(c) + 2, dtype=bool)
    word[0] = word[-1] = False
    np.not_equal(c, _SPACE, out=word[1:-1])
    edges = np.flatnonzero(word[1:] != word[:-1])
    return edges[0::2], edges[1::2]


def parse_decimals(line: str) -> np.ndarray | None:
    """The numbers of a line of space-separated plain decimals, or None when it holds anything
    else.

    Parameters
    ----------
    line : str
        Tokens separated by spaces; each an optional ``-``, then digits with at most one ``.``
        among them (``12``, ``-0.5``, ``3.``, ``.25``), with at least one and at most
        :data:`MAX_DIGITS` digits.

    Returns
    -------
    (n,) float64 or None
        The tokens' values, equal bit for bit to ``[float(t) for t in line.split()]``; None when
        a token is not of that form (the caller then reads the line token by token).
    """
    try:
        c = np.frombuffer(line.encode("ascii"), dtype=np.uint8)
    except UnicodeEncodeError:
        return None
    if not _PLAIN[c].all():
        return None
    starts, ends = _tokens(c)
    if len(starts) == 0:
        return np.zeros(0)
    minus = c[starts] == _MINUS
    dots = np.flatnonzero(c == _DOT)
    dot_token = np.searchsorted(starts, dots, side="right") - 1
    if np.count_nonzero(c == _MINUS) != np.count_nonzero(minus) or np.any(np.diff(dot_token) == 0):
        return None  # a '-' inside a token, or two points in one
    has_dot = np.zeros(len(starts), dtype=bool)
    has_dot[dot_token] = True
    digits = ends - starts - minus - has_dot
    if digits.min() < 1 or digits.max() > MAX_DIGITS:
        return None
    return _values(c, starts, ends, minus)


def _values(c: np.ndarray, starts: np.ndarray, ends: np.ndarray, minus: np.ndarray) -> np.ndarray:
    """The values of checked plain tokens (:func:`parse_decimals`): their digits read column by
    column, the tokens aligned on their last byte (Horner's rule on exact integers)."""
    width = int((ends - starts).max())
    whole = np.zeros(len(starts), dtype=np.int64)
    after = np.zeros(len(starts), dtype=np.int64)  # digits after the point
    seen_dot = np.zeros(len(starts), dtype=bool)
    for j in range(width):
        pos = ends - width + j
        inside = pos >= starts
        byte = c[np.maximum(pos, 0)]
        digit = inside & (byte >= _ZERO)
        whole = np.where(digit, whole * 10 + (byte.astype(np.int64) - _ZERO), whole)
        after += digit & seen_dot
        seen_dot |= inside & (byte == _DOT)
    values = whole.astype(np.float64) / _POW10[after]
    np.negative(values, out=values, where=minus)
    return values


__all__ = ["MAX_DIGITS", "parse_decimals"]
