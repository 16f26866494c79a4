"""The blocks a report page is made of (``templates/macros.html.j2`` renders them): a table of
cells as text, right-aligned where numeric, and a note. Numbers are formatted here (4
significant digits, ``n/a`` for missing or non-finite values); escaping is the templates'.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def text_of(value: object, spec: str = ".4g") -> str:
    """A cell's text: numbers to ``spec`` (4 significant digits), ``n/a`` for a missing or
    non-finite value, ``yes``/``no`` for a flag."""
    if value is None:
        return "n/a"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "n/a" if not math.isfinite(value) else format(float(value), spec)
    return str(value)


def table_block(
    columns: Sequence[str], rows: Sequence[Sequence[object]], caption: str = ""
) -> dict:
    """A table block: cells as text (numbers formatted, right-aligned by the template)."""
    cells = [
        [
            {
                "text": text_of(cell),
                "numeric": isinstance(cell, (int, float, np.number)) and not isinstance(cell, bool),
            }
            for cell in row
        ]
        for row in rows
    ]
    return {"kind": "table", "table": {"columns": list(columns), "rows": cells, "caption": caption}}


def note_block(text: str) -> dict:
    """A note block: a line of text."""
    return {"kind": "note", "text": text}
