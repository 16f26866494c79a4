"""The sheet's text, cell by cell, before pandas reads it (:func:`scan2morph.sheet.read_sheet`).

A base module (no pandas): the rules of a sheet's lines that pandas would get wrong silently.

- A ``#`` at the start of a line or of a cell begins a comment that runs to the end of the line;
  a ``#`` inside a cell is part of it (a path such as ``take#2.abs``: pandas' ``comment="#"``
  cut the path there and dropped the rest of the row).
- Empty cells past the header's columns (a trailing tab, as spreadsheets export) are dropped.
- A row with a filled cell past the header's columns is refused: pandas took the first column
  of such a sheet for its index and shifted every cell of every row one column left.
- A header without a tab is refused naming what the sheet looks separated by; so is a header
  with an empty column name (a trailing tab: pandas would call the column ``Unnamed: 8``).
- The text is UTF-8, or UTF-16 with its byte-order mark (:func:`sheet_text`).
"""

from __future__ import annotations

import re
from pathlib import Path

from scan2morph.errors import InputError


def sheet_text(path: str | Path) -> str:
    """A sheet's text: UTF-8 (with or without a byte-order mark), or UTF-16 with its mark (what
    a spreadsheet's "Unicode text" export writes).

    Raises
    ------
    InputError
        A spreadsheet's own file (a zip archive); bytes that are not UTF-8 (a sheet saved as
        Latin-1 or another code page): names the line and the byte.
    """
    raw = Path(path).read_bytes()
    if raw.startswith(b"PK\x03\x04"):  # a zip archive, as .xlsx and .ods files are
        raise InputError(
            path, "a zip file (an .xlsx or .ods spreadsheet?); expected tab-separated UTF-8 text"
        )
    encoding = "utf-16" if raw.startswith((b"\xff\xfe", b"\xfe\xff")) else "utf-8-sig"
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError(
            path,
            f"line {line}: byte {raw[exc.start]:#04x} is not {encoding.split('-sig')[0].upper()} "
            "text (a sheet saved in another encoding?); save it as UTF-8",
        ) from None


def tab_cells(path: str | Path, text: str) -> str:
    """The sheet's text without its comments and its empty cells past the header's columns.

    Parameters
    ----------
    path : str or path-like
        The sheet, named in the errors.
    text : str
        Its text.

    Returns
    -------
    str
        One line per line of ``text`` (a comment line left empty), cells separated by tabs.

    Raises
    ------
    InputError
        A header without a tab or with an empty column name (names the line); a row with a
        filled cell past the header's columns (names the row: 2 is the first row after the
        header, comments and blank lines not counted).
    """
    lines, width, row = text.splitlines(), 0, 1
    for k, line in enumerate(lines):
        cells = line.split("\t")
        comment = [i for i, cell in enumerate(cells) if cell.lstrip().startswith("#")]
        cells = cells[: comment[0]] if comment else cells
        lines[k] = "\t".join(cells)
        if not lines[k].strip():
            lines[k] = ""
            continue
        if not width and len(cells) == 1 and re.search(r",|\S +\S", cells[0]):
            raise InputError(
                path,
                f"header: no tab between the column names ({cells[0][:60]!r}); expected a "
                "tab-separated sheet (this one looks separated by commas or spaces)",
            )
        if not width and (empty := [i for i, c in enumerate(cells) if not c.strip()]):
            raise InputError(path, _unnamed(k + 1, empty[0], len(cells)))
        row, width = (row + 1, width) if width else (row, len(cells))
        if extra := [c for c in cells[width:] if c.strip()]:
            raise InputError(
                path,
                f"row {row}: {len(cells)} cells but the header has {width} columns (a tab too "
                f"many?; the extra: {extra[0][:40]!r})",
            )
        lines[k] = "\t".join(cells[:width])
    return "\n".join(lines) + "\n"


def _unnamed(line: int, column: int, n_cells: int) -> str:
    """The problem of a header whose column ``column`` (0-based) has no name."""
    if column == n_cells - 1:
        why = "a tab at the end of the header line"
    else:
        why = "two tabs in a row, or a tab at the start"
    return f"header (line {line}): column {column + 1} has no name ({why}?); remove the tab"


__all__ = ["sheet_text", "tab_cells"]
