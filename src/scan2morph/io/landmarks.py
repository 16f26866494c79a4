"""iBUG ``.pts`` landmark files.

Format::

    version: 1
    n_points: 68
    {
    x y
    ...
    }

iBUG coordinates are **1-based**: (1, 1) is the centre of the top-left pixel. Inside scan2morph
pixel coordinates are 0-based ((0, 0) is that centre), so reading subtracts 1 and writing adds 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scan2morph.errors import InputError, writing
from scan2morph.tol import N_IBUG


def read_pts(path: str | Path, n_points: int = N_IBUG) -> np.ndarray:
    """Read an iBUG ``.pts`` file.

    Parameters
    ----------
    path : str or Path
        The file.
    n_points : int
        The number of points expected (68 for iBUG-68).

    Returns
    -------
    points : (n_points, 2) float64
        0-based pixel coordinates (x = column, y = row).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected an iBUG .pts landmark file)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read as text: {exc}") from exc
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    header = {}
    i = 0
    while i < len(lines) and lines[i] != "{":
        key, sep, value = lines[i].partition(":")
        if not sep:
            raise InputError(path, f"header line {lines[i][:40]!r}: expected 'key: value' or '{{'")
        header[key.strip()] = value.strip()
        i += 1
    if i == len(lines):
        raise InputError(path, "missing '{' that opens the point list")
    try:
        declared = int(header["n_points"])
    except KeyError:
        raise InputError(path, "header 'n_points' missing") from None
    except ValueError:
        raise InputError(
            path, f"header 'n_points': not an integer ({header['n_points']!r})"
        ) from None
    if "}" not in lines[i + 1 :]:
        raise InputError(path, "missing '}' that closes the point list (truncated file?)")
    end = lines.index("}", i + 1)
    body = lines[i + 1 : end]
    if len(body) != declared:
        raise InputError(path, f"n_points says {declared} but the list has {len(body)} points")
    if declared != n_points:
        raise InputError(path, f"n_points: expected {n_points} (iBUG-68), got {declared}")
    rows = []
    for k, line in enumerate(body):
        parts = line.split()
        if len(parts) != 2:
            raise InputError(path, f"point {k + 1}: expected 'x y', got {line[:40]!r}")
        try:
            rows.append((float(parts[0]), float(parts[1])))
        except ValueError:
            raise InputError(
                path, f"point {k + 1}: non-numeric coordinate in {line[:40]!r}"
            ) from None
    points = np.asarray(rows, dtype=np.float64)
    if not np.all(np.isfinite(points)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(points), axis=1))[0]) + 1
        raise InputError(path, f"point {bad}: non-finite coordinate")
    return points - 1.0


def write_pts(path: str | Path, points: np.ndarray) -> None:
    """Write 0-based pixel coordinates (N, 2) as an iBUG ``.pts`` file (1-based)."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2:
        raise InputError(path, f"points: expected an (N, 2) array, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise InputError(path, "points: non-finite coordinate")
    lines = ["version: 1", f"n_points: {len(points)}", "{"]
    lines += [f"{x + 1.0:.4f} {y + 1.0:.4f}" for x, y in points]
    lines.append("}")
    with writing(path):
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
