"""A package's public names imported from its modules when first used (PEP 562).

A take's job is a process of its own (issue #35), and a package that imports all of its modules
up front makes every job pay for the ones it does not use: ``scan2morph.scan`` would bring the
stereo matcher to a job that only repairs a range image, ``scan2morph.io`` the glTF writer to
one that reads it. Such a package lists its names here instead; each is imported from its
module on first use and kept, so ``from scan2morph.scan import repair_range`` works as before.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping


def lazy_exports(
    package: str, exports: Mapping[str, tuple[str, ...]]
) -> tuple[Callable[[str], object], Callable[[], list[str]], list[str]]:
    """The module-level ``__getattr__``, ``__dir__`` and ``__all__`` of a lazy package.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping module -> names
        Each of the package's modules (relative name, e.g. ``"repair"``) and the public names
        the package takes from it.

    Returns
    -------
    getattr : callable
        Imports a listed name's module on first use, keeps the name in the package and
        returns it; an unlisted name raises ``AttributeError``.
    dir : callable
        The package's names, the listed ones included.
    all : list of str
        The listed names, sorted.
    """
    where = {name: f"{package}.{module}" for module, names in exports.items() for name in names}

    def getattr_(name: str) -> object:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(where[name]), name)
        setattr(sys.modules[package], name, value)
        return value

    def dir_() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(where))

    return getattr_, dir_, sorted(where)
