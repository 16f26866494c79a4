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

A file holds the 68 iBUG points or the 51 inner-face ones (iBUG-68 without the jawline 1-17,
as many datasets ship them); the readers return 68 rows either way, the jawline's rows NaN for a
51-point file (the landmarks stage then detects them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scan2morph.errors import InputError, writing
from scan2morph.io.text_file import utf8_text
from scan2morph.tol import N_IBUG

#: iBUG numbers (1-based) of the jawline, which a 51-point file leaves out.
JAWLINE = tuple(range(1, 18))
#: Point counts a landmark file may hold: iBUG-68, or its 51 inner-face points.
ACCEPTED_COUNTS = (N_IBUG, N_IBUG - len(JAWLINE))


def count_problem(count: int, unit: str = "points") -> str:
    """What is wrong with a landmark file of ``count`` points (``""`` when it is accepted)."""
    if count in ACCEPTED_COUNTS:
        return ""
    return (
        f"{count} {unit}; accepted: {ACCEPTED_COUNTS[0]} (iBUG-68) or {ACCEPTED_COUNTS[1]} "
        f"(iBUG-68 without the jawline {JAWLINE[0]}-{JAWLINE[-1]})"
    )


def as_ibug68(points: np.ndarray) -> np.ndarray:
    """68 rows from an accepted point set: a 51-point set gets NaN jawline rows in front.

    Parameters
    ----------
    points : (68, d) or (51, d) float

    Returns
    -------
    (68, d) float64
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) == N_IBUG:
        return points
    jaw = np.full((len(JAWLINE), points.shape[1]), np.nan)
    return np.concatenate([jaw, points])


def complete(points: np.ndarray | None) -> bool:
    """True when every one of the 68 points is given (no NaN row; False for None: no file)."""
    return points is not None and bool(np.isfinite(points).all())


#: The first line of the landmark files the pipeline writes for a take left out at its
#: landmarks (``results/{subject}/landmarks/{take}.pts`` and ``.xyz``): no points, the reason.
LEFT_OUT = "# no landmarks: "


def refuse_left_out(path: str | Path, text: str) -> None:
    """Refuse a landmark file that is the pipeline's record of a take left out at its landmarks
    (:data:`LEFT_OUT`): it holds no points to give back.

    Raises
    ------
    InputError
        Naming the file and the reason it records, and what to give instead.
    """
    if text.startswith(LEFT_OUT):
        reason = text.splitlines()[0].removeprefix(LEFT_OUT).strip()
        raise InputError(
            path,
            f"the pipeline's record of a take left out at its landmarks ({reason[:200]}), with "
            "no points to give back: leave the sheet's landmarks cell empty to detect them "
            "again, or give clicked ones",
        )


def read_pts(path: str | Path, n_points: int | None = None) -> np.ndarray:
    """Read an iBUG ``.pts`` file.

    Parameters
    ----------
    path : str or Path
        The file.
    n_points : int, optional
        The number of points expected; None accepts :data:`ACCEPTED_COUNTS` and returns 68
        rows (:func:`as_ibug68`).

    Returns
    -------
    points : (68, 2) or (n_points, 2) float64
        0-based pixel coordinates (x = column, y = row); NaN rows for the points a 51-point
        file leaves out.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected an iBUG .pts landmark file)")
    text = utf8_text(path)
    refuse_left_out(path, text)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise InputError(path, "the file is empty (expected an iBUG .pts landmark file)")
    header = {}
    i = 0
    while i < len(lines) and lines[i] != "{":
        if lines[i].startswith("#"):  # a comment (the pipeline's note on refused points)
            i += 1
            continue
        key, sep, value = lines[i].partition(":")
        if not sep and _numbers(lines[i]):
            xyz = len(lines[i].replace(",", " ").split()) == 3  # 'x y z': a mesh take's file
            raise InputError(
                path,
                f"header: {lines[i][:40]!r} is a point, but an iBUG .pts starts with a header "
                "('version: 1', 'n_points: 68', '{'; the points, then '}')"
                + (
                    "; 3D points 'x y z' are for a mesh take: give this take its .pts of image "
                    "points"
                    if xyz
                    else ""
                ),
            )
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
    if n_points is not None and declared != n_points:
        raise InputError(path, f"n_points: expected {n_points}, got {declared}")
    if n_points is None and (problem := count_problem(declared)):
        raise InputError(path, f"n_points: {problem}")
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
    return points - 1.0 if n_points is not None else as_ibug68(points - 1.0)


def _numbers(line: str) -> bool:
    """True when ``line`` is two or three numbers (a point where a header line should be)."""
    parts = line.replace(",", " ").split()
    try:
        [float(p) for p in parts]
    except ValueError:
        return False
    return len(parts) in (2, 3)


def write_pts(path: str | Path, points: np.ndarray, comment: str | None = None) -> None:
    """Write 0-based pixel coordinates (N, 2) as an iBUG ``.pts`` file (1-based); ``comment``:
    a first line ``# comment`` (:func:`read_pts` skips it)."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2:
        raise InputError(path, f"points: expected an (N, 2) array, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise InputError(path, "points: non-finite coordinate")
    lines = [f"# {comment}"] if comment else []
    lines += ["version: 1", f"n_points: {len(points)}", "{"]
    lines += [f"{x + 1.0:.4f} {y + 1.0:.4f}" for x, y in points]
    lines.append("}")
    with writing(path):
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_landmarks3d(
    path: str | Path, points: np.ndarray, comment: str | None = None, fmt: str = ".6g"
) -> None:
    """Write 3D points (N, 3) as ``x y z`` lines, one point a line in the given order: the form
    a mesh take's landmark file takes (:func:`~scan2morph.io.mesh_scan.read_landmarks3d`), and
    a point cloud MeshLab and CloudCompare open (``.xyz``, without ``comment``).

    Parameters
    ----------
    path : str or Path
    points : (N, 3) float
        In the units and frame the reader is to get them in.
    comment : str, optional
        A first line ``# comment``.
    fmt : str
        Each coordinate's format spec (default 6 significant digits: 1 um of a face in mm or
        in metres).
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(path, f"points: expected an (N, 3) array, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise InputError(path, "points: non-finite coordinate")
    lines = [] if comment is None else [f"# {comment}"]
    lines += [" ".join(format(c, fmt) for c in p) for p in points]
    with writing(path):
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
