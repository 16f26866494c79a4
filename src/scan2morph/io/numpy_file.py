"""NumPy files a user gives (a range image's ``.npz``, a depth frame's ``.npy``/``.npz``) told
apart by their first bytes before :func:`numpy.load` reads them."""

from __future__ import annotations

from pathlib import Path

from scan2morph.errors import InputError

#: The first bytes of NumPy's files: an ``.npz`` is a zip archive (an empty one starts ``PK``
#: ``05 06``), an ``.npy`` starts with its magic string.
NUMPY_MAGIC = {".npz": (b"PK\x03\x04", b"PK\x05\x06"), ".npy": (b"\x93NUMPY",)}
_NUMPY_KIND = {".npz": "a NumPy .npz (a zip archive of named arrays)", ".npy": "a NumPy .npy array"}


def check_numpy_file(path: Path, field: str) -> None:
    """Refuse a file whose first bytes are not the NumPy format its suffix names, before
    :func:`numpy.load` reads it (which calls any other file pickled data and suggests loading
    it unsafely, reads an ``.npz`` named ``.npy`` as an array of its key names, and fails on an
    ``.npy`` named ``.npz`` with a context-manager error).

    Parameters
    ----------
    path : Path
        An ``.npz`` or ``.npy`` file that exists.
    field : str
        The sheet column, for the message (``xyz``, ``depth``).

    Raises
    ------
    InputError
        Naming what the file is instead: empty, the other NumPy format, or not NumPy data.
    """
    suffix = path.suffix.lower()
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:  # e.g. no permission: not a traceback
        raise InputError(path, f"{field}: cannot read: {exc.strerror or exc}") from None
    if head.startswith(NUMPY_MAGIC[suffix]):
        return
    other = next((k for k, magic in NUMPY_MAGIC.items() if head.startswith(magic)), None)
    if not head:
        got = "an empty file (0 bytes)"
    elif other is not None:
        got = f"{_NUMPY_KIND[other]} named {suffix}"
    else:
        got = f"a file starting with {head!r}, not NumPy data"
    raise InputError(path, f"{field}: expected {_NUMPY_KIND[suffix]}, got {got}")


__all__ = ["NUMPY_MAGIC", "check_numpy_file"]
