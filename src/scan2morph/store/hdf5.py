"""The versioned per-subject HDF5 store and the HDF5 "parts" the stages hand to it.

Each stage writes a *part*: a small HDF5 file whose datasets already sit at their final paths in
the subject's store (for example ``/takes/car/mesh/vertices``). The store rule merges the parts of a
subject into ``results/{subject}/{subject}.h5`` and adds the root attributes of the contract.
Writing builds the file in memory and writes its bytes to a temporary file that is renamed into
place (:func:`hdf5_output`), so a failed job never leaves a half-written store behind, the file
gets the mode the user's umask gives any new file (:func:`scan2morph.jobs.atomic_output`), and
a full disk is one clear error (:class:`~scan2morph.errors.OutputError`) raised by Python's own
write: HDF5 never writes to a full disk, whose failures it reports from finalisers, as
tracebacks on stderr and at worst a crash.
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np

from scan2morph.errors import InputError, writing
from scan2morph.jobs import atomic_output
from scan2morph.version import __version__

#: Semantic version of the store layout (``schemas/store.layout.yaml``).
FORMAT_VERSION = "1.11.0"
#: Datasets at least this large are chunked and gzip-compressed.
_COMPRESS_BYTES = 1 << 16


@contextmanager
def hdf5_output(path: str | Path, mode: str = "w") -> Iterator[h5py.File]:
    """An HDF5 file built in memory and written to ``path`` when the block ends without error.

    Parameters
    ----------
    path : str or Path
        The file (replaced atomically).
    mode : ``"w"`` or ``"a"``
        A new file, or ``path``'s content to add to.

    Raises
    ------
    OutputError
        The disk is full (one line naming ``path``); ``path`` is left as it was.
    """
    path = Path(path)
    buffer = io.BytesIO(path.read_bytes() if mode == "a" else b"")
    with h5py.File(buffer, mode) as h5:
        yield h5
    write_file(path, buffer.getbuffer())


def write_file(path: str | Path, content: bytes | memoryview) -> None:
    """Write an HDF5 file's bytes (built in memory) to ``path``, replaced atomically.

    Raises
    ------
    OutputError
        The disk is full (one line naming ``path``); ``path`` is left as it was.
    """
    path = Path(path)
    with atomic_output(path) as tmp, writing(path):
        tmp.write_bytes(content)


def _write_dataset(h5: h5py.File, name: str, value) -> None:
    if isinstance(value, str) or (
        isinstance(value, (list, tuple, np.ndarray))
        and len(value)
        and isinstance(np.asarray(value).flat[0], str)
    ):
        h5.create_dataset(name, data=np.asarray(value, dtype=object), dtype=h5py.string_dtype())
        return
    arr = np.asarray(value)
    if arr.dtype.kind in "US" or (arr.dtype.kind == "O" and arr.size == 0):
        # text, or an empty list of names (no element says so, an object array means text)
        h5.create_dataset(name, data=arr.astype(object), dtype=h5py.string_dtype())
        return
    kwargs = {}
    if arr.nbytes >= _COMPRESS_BYTES and arr.ndim >= 1:
        kwargs = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
    h5.create_dataset(name, data=arr, **kwargs)


def _set_attrs(obj, attrs: Mapping) -> None:
    for key, value in attrs.items():
        if isinstance(value, (dict, list)) and not isinstance(value, np.ndarray):
            value = json.dumps(value, sort_keys=True)
        obj.attrs[key] = value


def attr_value(value):
    """An attribute as written by :func:`write_part`, back as Python: bytes decoded, JSON-valued
    text (dicts and lists are written as JSON) parsed, numpy scalars as Python scalars."""
    if isinstance(value, bytes):
        value = value.decode()
    if isinstance(value, str) and value[:1] in "{[":
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value.item() if isinstance(value, np.generic) else value


def write_part(
    path: str | Path,
    datasets: Mapping[str, object],
    attrs: Mapping[str, Mapping] | None = None,
) -> None:
    """Write a stage's part file.

    Parameters
    ----------
    path : str or Path
        Output ``.h5`` file (replaced atomically).
    datasets : mapping of str to array-like
        Absolute store paths (``/takes/car/mesh/vertices``) to arrays or strings.
    attrs : mapping of str to mapping, optional
        Group or dataset path to its attributes; ``"/"`` is the root.
    """
    with hdf5_output(path) as h5:
        for name, value in datasets.items():
            _write_dataset(h5, name, value)
        for name, group_attrs in (attrs or {}).items():
            obj = h5.require_group(name) if name not in h5 else h5[name]
            _set_attrs(obj, group_attrs)


def read_part(path: str | Path, prefix: str = "/") -> dict[str, np.ndarray]:
    """Read every dataset below ``prefix`` of a part (or a store) into a dict keyed by path."""
    out: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as h5:
        root = h5[prefix]

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                value = obj[()]
                if obj.dtype.kind == "O":
                    value = obj.asstr()[()]
                out[f"{root.name.rstrip('/')}/{name}"] = value

        root.visititems(visit)
    return out


def read_attrs(path: str | Path, name: str = "/", missing_ok: bool = False) -> dict:
    """Attributes of one group or dataset of a part or store; with ``missing_ok``, ``{}`` when
    the part has no ``name`` (a left-out take's part records only why it was left out)."""
    with h5py.File(path, "r") as h5:
        if missing_ok and name not in h5:
            return {}
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in h5[name].attrs.items()}


def read_group_attrs(files: Mapping[str, str | Path], group) -> dict[str, dict]:
    """The attributes of ``group(key)`` (a store path) in each key's file, under that path; a
    file without the group, or without attributes on it, gives none."""
    out = {}
    for key, path in files.items():
        attrs = read_attrs(path, group(key), missing_ok=True)
        if attrs:
            out[group(key)] = attrs
    return out


def merge_parts(
    path: str | Path,
    parts: Iterable[str | Path],
    subject: str,
    config_sha256: str,
    exclude: Iterable[str] = (),
    provenance: Mapping[str, object] | None = None,
) -> None:
    """Merge stage parts into the subject's versioned store.

    Parameters
    ----------
    path : str or Path
        ``results/{subject}/{subject}.h5`` (replaced atomically).
    parts : iterable of paths
        Part files; a path present in two parts is an error.
    subject : str
        Subject id (root attribute).
    config_sha256 : str
        Hash of the configuration the run used (root attribute).
    exclude : iterable of str, optional
        Groups left out of the store (e.g. ``/takes/car`` of a take left out of its subject).
    provenance : mapping, optional
        More root attributes: which code made the store
        (:func:`scan2morph.provenance.run_provenance`).

    Notes
    -----
    The input checksums that the ingest stage puts on each ``/takes/{take}`` group (attributes
    ``input_sha256_<role>``) are gathered into the root attribute ``input_sha256``: a JSON object
    take -> role -> hex digest.
    """
    with hdf5_output(path) as out:
        merge_into(out, parts, subject, config_sha256, exclude, provenance)


def merge_into(
    out: h5py.File,
    parts: Iterable[str | Path],
    subject: str,
    config_sha256: str,
    exclude: Iterable[str] = (),
    provenance: Mapping[str, object] | None = None,
) -> None:
    """:func:`merge_parts` into an open (e.g. in-memory, :func:`hdf5_output`) file."""
    for part in parts:
        with h5py.File(part, "r") as src:
            _merge_group(src, out, Path(part), frozenset(exclude))
    out.attrs["format_version"] = FORMAT_VERSION
    out.attrs["scan2morph_version"] = __version__
    out.attrs["config_sha256"] = config_sha256
    out.attrs["subject"] = subject
    out.attrs["units"] = "mm"
    for key, value in (provenance or {}).items():
        out.attrs[key] = value
    checksums = {
        take: {
            key.removeprefix("input_sha256_"): str(value)
            for key, value in group.attrs.items()
            if key.startswith("input_sha256_")
        }
        for take, group in out.get("takes", {}).items()
    }
    out.attrs["input_sha256"] = json.dumps(checksums, sort_keys=True)


#: Groups that every part of a failed take repeats (its failure record): merged once.
_REPEATED = "/failed/"


def _merge_group(src: h5py.Group, dst: h5py.Group, part: Path, exclude: frozenset) -> None:
    for key, value in src.attrs.items():
        dst.attrs[key] = value
    for name, obj in src.items():
        if obj.name in exclude:
            continue
        if isinstance(obj, h5py.Dataset):
            if name in dst:
                if obj.name.startswith(_REPEATED) and _same(obj, dst[name]):
                    continue
                raise InputError(
                    part, f"dataset {obj.name} is already in the store (two parts write it)"
                )
            src.copy(obj, dst, name=name)
        else:
            _merge_group(obj, dst.require_group(name), part, exclude)


def _same(a: h5py.Dataset, b: h5py.Dataset) -> bool:
    read = (lambda d: d.asstr()[()]) if a.dtype.kind == "O" else (lambda d: d[()])
    return bool(np.array_equal(read(a), read(b)))


def open_store(path: str | Path) -> h5py.File:
    """Open a subject store for reading, refusing an unknown major format version.

    Raises
    ------
    InputError
        Not an HDF5 file, no ``format_version``, or a major version this library does not read.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "store not found")
    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(path, f"not an HDF5 file: {exc}") from exc
    version = h5.attrs.get("format_version")
    if version is None:
        h5.close()
        raise InputError(path, "root attribute 'format_version' missing: not a scan2morph store")
    version = version.decode() if isinstance(version, bytes) else str(version)
    major = version.split(".")[0]
    if major != FORMAT_VERSION.split(".")[0]:
        h5.close()
        raise InputError(
            path,
            f"format_version {version} is not readable by scan2morph {__version__} "
            f"(reads {FORMAT_VERSION.split('.')[0]}.x); convert it or use a matching release",
        )
    return h5


def read_parts(paths: Iterable[str | Path]) -> dict[str, np.ndarray]:
    """Every dataset of several parts, merged into one dict keyed by store path."""
    out: dict[str, np.ndarray] = {}
    for path in paths:
        out |= read_part(path)
    return out


def write_datasets(path: str | Path, datasets: Mapping[str, object]) -> None:
    """Add datasets to an existing part or store (written as :func:`write_part` writes them)."""
    with hdf5_output(path, "a") as h5:
        write_into(h5, datasets)


def write_into(h5: h5py.File, datasets: Mapping[str, object]) -> None:
    """Add datasets to an open file (as :func:`write_part` writes them)."""
    for name, value in datasets.items():
        _write_dataset(h5, name, value)
