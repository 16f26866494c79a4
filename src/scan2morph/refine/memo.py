"""Work shared between the refinements of one subject's takes: a scoped memo of the pure steps
that many refinements repeat on the same data.

The click-noise error bar (:mod:`scan2morph.motion.uncertainty`) refines every viseme in every
draw: the neutral's side of the correlation (its pull-back, its high-pass, its shape image) is
the same for every viseme of a draw, and a take's own images are the same in every draw. Inside
:func:`sharing` those steps are computed once: each is keyed by a digest of its whole input
(every array's dtype, shape and bytes, and every number), so a hit returns exactly what the
computation would, bit for bit. Outside it (the pipeline's own refinement) nothing is kept.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

#: Bytes of results a scope keeps (the least recently used go first; synth02 at 640 x 480 needs
#: 64 MB for every reuse, and the job peaks at 441 MB against 351 MB without the sharing).
KEPT_BYTES = 64 * 2**20
_SCOPES: list[_Memo] = []


class _Memo:
    """Results by key, least recently used first, at most :data:`KEPT_BYTES` of arrays."""

    def __init__(self, kept: int):
        self.kept, self.size = kept, 0
        self.items: OrderedDict[bytes, tuple[object, int]] = OrderedDict()
        self.counts: dict[str, list[int]] = {}

    def get(self, name: str, key: bytes, compute: Callable[[], object]) -> object:
        count = self.counts.setdefault(name, [0, 0])
        if key in self.items:
            self.items.move_to_end(key)
            count[0] += 1
            return self.items[key][0]
        count[1] += 1
        value = compute()
        size = _frozen(value)
        self.items[key] = (value, size)
        self.size += size
        while self.size > self.kept and len(self.items) > 1:
            self.size -= self.items.popitem(last=False)[1][1]
        return value


def _frozen(value) -> int:
    """Make the arrays in ``value`` (an array, or a tuple or list of them and other values)
    read-only, so that no caller changes what another is handed; their bytes."""
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
        return value.nbytes
    if isinstance(value, tuple | list):
        return sum(_frozen(v) for v in value)
    return 0


def digest(*parts) -> bytes:
    """A digest of arrays (dtype, shape, bytes) and plain values (their ``repr``)."""
    h = hashlib.sha1(usedforsecurity=False)  # a cache key, not a signature: the fastest here
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.data if a.size else b"")
        else:
            h.update(repr(p).encode())
        h.update(b"|")
    return h.digest()


@contextmanager
def sharing(kept_bytes: int = KEPT_BYTES) -> Iterator[dict[str, list[int]]]:
    """A scope in which :func:`shared` steps are computed once per input; it yields the
    scope's counts, step name -> ``[hits, computed]``."""
    memo = _Memo(kept_bytes)
    _SCOPES.append(memo)
    try:
        yield memo.counts
    finally:
        _SCOPES.pop()


def active() -> bool:
    """Whether a :func:`sharing` scope is open."""
    return bool(_SCOPES)


def shared(name: str, parts: tuple, compute: Callable[[], object]) -> object:
    """``compute()``, or its result for the same ``name`` and ``parts`` (the whole input of
    the step) when the open :func:`sharing` scope has it; without a scope, ``compute()``.
    Arrays in a kept result are read-only."""
    if not _SCOPES:
        return compute()
    return _SCOPES[-1].get(name, digest(name, *parts), compute)


__all__ = ["KEPT_BYTES", "active", "digest", "shared", "sharing"]
