"""A user's text file read as UTF-8, its bad bytes named by line (not Python's codec message)."""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from scan2morph.errors import InputError

#: UTF-8's byte-order mark, which Windows editors write at the start of a text file.
BOM = b"\xef\xbb\xbf"


def utf8_text(path: str | PathLike[str], bom: bool = False) -> str:
    """A text file's text, or an :class:`InputError` naming the line and the byte that is not
    UTF-8 (a file saved as Latin-1 or another code page).

    Parameters
    ----------
    path : str or path-like
        The file (it exists).
    bom : bool
        Drop a byte-order mark at the start (as Windows editors save); without, it is read as
        a character.

    Raises
    ------
    InputError
        The file cannot be read, or its bytes are not UTF-8 (the line and the byte counted in
        the file as it is, byte-order mark included).
    """
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None
    skip = len(BOM) if bom and raw.startswith(BOM) else 0
    try:
        return raw[skip:].decode("utf-8")
    except UnicodeDecodeError as exc:
        at = skip + exc.start
        line = raw[:at].count(b"\n") + 1
        raise InputError(
            path,
            f"line {line}: byte {raw[at]:#04x} is not UTF-8 text (saved as Latin-1 or another "
            "code page?); expected UTF-8",
        ) from None


__all__ = ["BOM", "utf8_text"]
