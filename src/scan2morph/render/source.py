"""What the figures read: the subject store as a mapping, its takes by kind, checked arrays.

The figure functions take any ``Mapping[str, ndarray]`` keyed by store path (``/pca/mean``): a
dict in tests, or :class:`StoreMapping`, which reads a store's datasets on demand (a subject's
store holds every take's range images; a figure needs only a few arrays).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

import h5py
import numpy as np

from scan2morph.errors import InputError
from scan2morph.render.views import View, face_view
from scan2morph.store import open_store, paths


class StoreMapping(Mapping):
    """Read-only, lazy mapping of store path -> array over an open subject store.

    Use as a context manager (closes the file). Strings come back as ``str`` arrays.

    Parameters
    ----------
    path : str or Path
        ``results/{subject}/{subject}.h5``; its format version is checked.
    """

    def __init__(self, path: str | Path):
        self.source = str(path)
        self._h5 = open_store(path)
        keys: list[str] = []
        self._h5.visititems(
            lambda name, obj: keys.append(f"/{name}") if isinstance(obj, h5py.Dataset) else None
        )
        self._keys = keys
        self._cache: dict[str, np.ndarray] = {}

    def __getitem__(self, key: str) -> np.ndarray:
        if key not in self._cache:
            if key not in self._h5 or not isinstance(self._h5[key], h5py.Dataset):
                raise KeyError(key)
            obj = self._h5[key]
            self._cache[key] = obj.asstr()[()] if obj.dtype.kind == "O" else obj[()]
        return self._cache[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def close(self) -> None:
        self._h5.close()

    def __enter__(self) -> StoreMapping:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def source_of(store: Mapping) -> str:
    """Label of a store for error messages (its path, or ``"store"``)."""
    return getattr(store, "source", "store")


def need(store: Mapping, key: str, what: str) -> np.ndarray:
    """A dataset that a figure cannot do without.

    Raises
    ------
    InputError
        Missing, naming the dataset and the figure (``what``).
    """
    try:
        return np.asarray(store[key])
    except KeyError:
        raise InputError(
            source_of(store), f"dataset {key} is missing (needed for {what})"
        ) from None


def n_vertices(store: Mapping) -> int:
    """V, the template's vertex count."""
    return len(need(store, paths.template("vertices2d"), "every mesh figure"))


def mesh(store: Mapping, key: str, what: str) -> np.ndarray:
    """A (V, 3) vertex array of the store, checked against the template's V."""
    value = need(store, key, what).astype(np.float64)
    v = n_vertices(store)
    if value.shape != (v, 3):
        raise InputError(
            source_of(store), f"dataset {key}: expected shape ({v}, 3), got {value.shape}"
        )
    return value


def groups(store: Mapping, root: str, dataset: str) -> list[str]:
    """The ids under ``root`` that hold ``dataset`` (:func:`paths.ids`), in sorted order."""
    return sorted(paths.ids(store, root, dataset))


def viseme_takes(store: Mapping) -> list[str]:
    """Takes with a viseme model, sorted."""
    return groups(store, paths.VISEMES, "model")


def expression_takes(store: Mapping) -> list[str]:
    """Takes with an expression displacement field, sorted."""
    return groups(store, paths.EXPRESSIONS, "displacement")


def neutral_take(store: Mapping) -> str:
    """The neutral take: the one meshed take that is neither a viseme nor an expression, nor a
    take left out of the models for failing its alignment gate (``/takes/{take}/align/ok``).

    Raises
    ------
    InputError
        None or several such takes.
    """
    takes = groups(store, paths.TAKES, "mesh/vertices")
    others = set(viseme_takes(store)) | set(expression_takes(store))
    neutral = [
        t
        for t in takes
        if t not in others and bool(np.asarray(store.get(paths.align(t, "ok"), True)))
    ]
    if len(neutral) != 1:
        raise InputError(
            source_of(store),
            f"{paths.TAKES}: expected exactly one neutral take (meshed, not a viseme or expression), found {neutral}",
        )
    return neutral[0]


def example_take(store: Mapping) -> str | None:
    """The take shown next to the neutral in the fit and motion figures.

    The viseme with the largest motion (an open mouth shows the method best), else the expression
    with the largest displacement, else None.
    """
    for takes, key in (
        (viseme_takes(store), lambda t: paths.viseme(t, "motion")),
        (expression_takes(store), lambda t: paths.expression(t, "displacement")),
    ):
        sizes = {
            t: float(np.nansum(np.asarray(store[key(t)], dtype=float) ** 2))
            for t in takes
            if key(t) in store
        }
        if sizes:
            return max(sizes, key=sizes.get)
    return None


def fiducials(store: Mapping) -> dict[str, int]:
    """Fiducial name -> vertex index, from ``/template/fiducials``."""
    names = need(store, paths.template("fiducials/names"), "fiducials")
    indices = need(store, paths.template("fiducials/indices"), "fiducials")
    if names.shape != indices.shape:
        raise InputError(
            source_of(store),
            f"{paths.FIDUCIALS}: names and indices differ in length",
        )
    return {str(n): int(i) for n, i in zip(names, indices, strict=True)}


def template_faces(store: Mapping, what: str) -> np.ndarray:
    """The template's faces (F, 3) int64."""
    return need(store, paths.template("faces"), what).astype(np.int64)


def neutral_view(store: Mapping[str, np.ndarray], what: str) -> View:
    """The view of the neutral frame (every aligned mesh and model lives in it).

    Derived from the neutral base model (complete, no NaN) when the store has it, else from the
    neutral take's mesh.
    """
    key = paths.neutral("vertices")
    if key not in store:
        key = paths.mesh(neutral_take(store), "vertices")
    vertices = mesh(store, key, what)
    xy = need(store, paths.template("vertices2d"), what)
    return face_view(vertices, template_faces(store, what), xy, source=source_of(store))
