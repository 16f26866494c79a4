"""Range images: FRGC ``.abs`` / ``.abs.gz`` and ``.npz``.

A range image is ``xyz`` (H, W, 3) float64 in mm, NaN where the scanner saw nothing, in the
take's scanner frame. Pixel (row r, column c) of ``xyz`` corresponds to pixel (r, c) of the color
image taken with it.

FRGC ``.abs`` layout (text)::

    480 rows
    640 columns
    pixels (flag X Y Z):
    <R*C flags 0/1>
    <R*C X values>
    <R*C Y values>
    <R*C Z values>

Values are row-major from the top row; invalid pixels have flag 0 and coordinates -999999.
"""

from __future__ import annotations

import gzip
import io
import re
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError, writing
from scan2morph.io.decimal_text import parse_decimals
from scan2morph.io.numpy_file import check_numpy_file
from scan2morph.io.text_file import BOM

#: The placeholder FRGC writes for the coordinates of a pixel without data.
ABS_INVALID = -999999.0
#: Largest R*C an ``.abs`` header may promise (FRGC scans are 640x480; 50 Mpx allows any
#: scanner): a larger header is refused before anything is read or allocated.
MAX_ABS_PIXELS = 50_000_000
#: The first two bytes of a gzip stream.
GZIP_MAGIC = b"\x1f\x8b"
#: Least share of a range image's pixels with data at which one exact point repeated at all of
#: them is a placeholder for "no data" (0, or FRGC's -999999, written where NaN was meant): the
#: pixels of a scanner see distinct points (only the rays' origin is common to them), so a real
#: scan repeats no point at more than a few pixels.
PLACEHOLDER_SHARE = 0.01

_HEADER_RE = (
    re.compile(r"^\s*(\d+)\s+rows\s*$", re.IGNORECASE),
    re.compile(r"^\s*(\d+)\s+columns\s*$", re.IGNORECASE),
    re.compile(r"^\s*pixels\s*\(flag\s+X\s+Y\s+Z\)\s*:?\s*$", re.IGNORECASE),
)


def _open_text(path: Path, mode: str):
    """A range text file opened as text: gzip-compressed when written to a name ending in
    ``.gz`` (any case), and when read from a file starting with gzip's magic bytes, whatever its
    name (an ``.ABS.GZ``, or a compressed file named ``.abs``)."""
    if mode == "w":
        if path.name.lower().endswith(".gz"):  # mtime=0: the same data gives the same bytes
            # level 6 (gzip's own default): as small as 9 on range text, 3x faster (0.8 s a
            # 640 x 480 scan against 2.4 s)
            raw = gzip.GzipFile(path, "wb", compresslevel=6, mtime=0)
            return io.TextIOWrapper(raw, encoding="ascii", newline="\n")
        return open(path, mode, encoding="ascii", newline="\n")
    with open(path, "rb") as fh:
        compressed = fh.read(2) == GZIP_MAGIC
    if compressed:
        return gzip.open(path, mode + "t", encoding="ascii", newline="\n")
    return open(path, mode, encoding="ascii", newline="\n")


def _not_ascii(exc: UnicodeDecodeError) -> str:
    """The message for an ``.abs`` whose text is not ASCII (the decoder's own names a codec and
    a position in a block, not what the user can change)."""
    if exc.object[: len(BOM)] == BOM and exc.start < len(BOM):
        return (
            "the file starts with a byte-order mark (BOM, as an editor saves UTF-8 text); "
            "expected FRGC .abs text in plain ASCII: save it without BOM"
        )
    byte = exc.object[exc.start]
    return f"byte {byte:#04x} is not ASCII text; expected FRGC .abs text (ASCII numbers)"


def read_abs(path: str | Path) -> np.ndarray:
    """Read an FRGC ``.abs`` or ``.abs.gz`` range image.

    Parameters
    ----------
    path : str or Path
        The file; read as gzip when it starts with gzip's magic bytes (whatever its name).

    Returns
    -------
    xyz : (H, W, 3) float64
        Coordinates in mm; NaN where the flag is 0.

    Raises
    ------
    InputError
        Missing file, bad header, truncated data, wrong value counts or non-numeric values.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected an FRGC .abs or .abs.gz range image)")
    try:
        with _open_text(path, "r") as fh:
            lines = [fh.readline() for _ in range(3)]
            lines = [ln.rstrip("\r\n") for ln in lines if ln]
            if len(lines) < 3:
                raise InputError(
                    path,
                    "truncated header: expected 'R rows', 'C columns', 'pixels (flag X Y Z):'",
                )
            rows, cols = _abs_header(lines, path)
            lines += fh.read().splitlines()
    except EOFError as exc:
        raise InputError(path, f"truncated gzip stream: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise InputError(path, _not_ascii(exc)) from None
    except OSError as exc:
        raise InputError(path, f"cannot read as FRGC .abs text: {exc}") from exc
    n = rows * cols
    data_lines = [ln for ln in lines[3:] if ln.strip()]
    names = ("flag", "X", "Y", "Z")
    if len(data_lines) < 4:
        missing = ", ".join(names[len(data_lines) :])
        raise InputError(path, f"truncated: expected 4 data lines (flag X Y Z), missing {missing}")
    if len(data_lines) > 4:
        raise InputError(path, f"expected 4 data lines (flag X Y Z), found {len(data_lines)}")
    arrays = []
    for name, line in zip(names, data_lines, strict=True):
        values = parse_decimals(line)  # plain decimals at once; else token by token, below
        if values is not None and len(values) == n:
            arrays.append(values)
            continue
        tokens = line.split()
        if len(tokens) != n:
            hint = " (truncated file?)" if name == "Z" and len(tokens) < n else ""
            raise InputError(
                path, f"line '{name}': expected {rows}*{cols} = {n} values, got {len(tokens)}{hint}"
            )
        try:
            arrays.append(np.array(tokens, dtype=np.float64))
        except ValueError:
            bad = next(t for t in tokens if not _is_number(t))
            raise InputError(path, f"line '{name}': non-numeric value {bad[:20]!r}") from None
    flag, x, y, z = arrays
    if not np.all((flag == 0) | (flag == 1)):
        raise InputError(path, "line 'flag': expected only 0 or 1 values")
    xyz = np.stack([x, y, z], axis=-1).reshape(rows, cols, 3)
    valid = (flag == 1).reshape(rows, cols)
    if not np.all(np.isfinite(xyz[valid])):
        raise InputError(path, "X/Y/Z: non-finite value at a pixel flagged valid")
    xyz[~valid] = np.nan
    # the format's own "no data" is the flag column: placeholders at pixels flagged 1 are refused
    _check_placeholder(xyz, path, "X/Y/Z", "pixels flagged valid", "flag such pixels 0")
    return xyz


def _abs_header(lines: list[str], path: Path) -> tuple[int, int]:
    """Rows and columns of an ``.abs`` header's three lines; refuses a size that makes no sense."""
    dims = []
    for i, (line, pattern, what) in enumerate(
        zip(
            lines[:3],
            _HEADER_RE,
            ("'<R> rows'", "'<C> columns'", "'pixels (flag X Y Z):'"),
            strict=True,
        )
    ):
        m = pattern.match(line)
        if m is None:
            raise InputError(path, f"header line {i + 1}: expected {what}, got {line[:60]!r}")
        if m.groups():
            dims.append(int(m.group(1)))
    rows, cols = dims
    if rows <= 0 or cols <= 0:
        raise InputError(path, f"header: expected positive rows and columns, got {rows} x {cols}")
    if rows * cols > MAX_ABS_PIXELS:
        raise InputError(
            path,
            f"header: {rows} rows x {cols} columns = {rows * cols:.3g} pixels, expected at most "
            f"{MAX_ABS_PIXELS:.3g} (a corrupt header?); refused before reading the data",
        )
    return rows, cols


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def write_abs(path: str | Path, xyz: np.ndarray) -> None:
    """Write a range image as FRGC ``.abs`` (gzip-compressed when the name ends in ``.gz``).

    Parameters
    ----------
    path : str or Path
        Output file.
    xyz : (H, W, 3) float
        Coordinates in mm; NaN pixels are written with flag 0 and -999999.

    Notes
    -----
    Values are written with 6 decimals (1 nm), far below any scanner's noise.
    """
    xyz = _check_xyz(xyz, path)
    rows, cols = xyz.shape[:2]
    valid = np.all(np.isfinite(xyz), axis=-1).reshape(-1)
    flat = xyz.reshape(-1, 3).copy()
    flat[~valid] = ABS_INVALID
    path = Path(path)
    with writing(path), _open_text(path, "w") as fh:
        fh.write(f"{rows} rows\n{cols} columns\npixels (flag X Y Z):\n")
        fh.write(" ".join(np.where(valid, "1", "0")) + "\n")
        # one format call a row: 0.24 s for a 640 x 480 scan's three rows, numpy.char.mod 0.73 s
        line = " ".join(["%.6f"] * len(flat)) + "\n"
        for k in range(3):
            fh.write(line % tuple(flat[:, k].tolist()))


def _check_xyz(xyz: np.ndarray, source) -> np.ndarray:
    xyz = np.asarray(xyz)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or xyz.shape[0] == 0 or xyz.shape[1] == 0:
        raise InputError(source, f"xyz: expected an (H, W, 3) array, got shape {xyz.shape}")
    if not np.issubdtype(xyz.dtype, np.floating):
        raise InputError(source, f"xyz: expected float values in mm, got dtype {xyz.dtype}")
    return xyz.astype(np.float64, copy=False)


def _check_placeholder(xyz: np.ndarray, source, field: str, which: str, fix: str) -> None:
    """Refuse a range image that holds one exact point at :data:`PLACEHOLDER_SHARE` or more of
    its pixels with data: a placeholder for "no data" (0 or -999999), which would otherwise be
    read as a valid point (the fit then spans the scene, 1-6 m deep).

    Parameters
    ----------
    xyz : (H, W, 3) float64, NaN = no data
    source : str or path-like
        The file, named in the error.
    field : str
        The data's key or lines in the file (``key 'xyz'``, ``X/Y/Z``).
    which, fix : str
        The pixels counted (``pixels``) and what to do instead, for the message.

    Raises
    ------
    InputError
        Naming the point and its share of the image.
    """
    flat = xyz.reshape(-1, 3)
    flat = flat[np.isfinite(flat).all(axis=1)]
    least = max(2.0, PLACEHOLDER_SHARE * len(flat))
    values, counts = np.unique(flat[:, 2], return_counts=True)  # a repeated point repeats its z
    if not len(counts) or counts.max() < least:
        return
    point = flat[flat[:, 2] == values[np.argmax(counts)]][0]
    same = int((flat == point).all(axis=1).sum())
    if same >= least:
        share = same / (xyz.shape[0] * xyz.shape[1])
        coords = ", ".join(f"{v:g}" for v in point)
        raise InputError(
            source, f"{field}: {share:.0%} of the {which} are exactly ({coords}): {fix}"
        )


def read_npz_range(path: str | Path) -> np.ndarray:
    """Read a range image from an ``.npz`` with key ``xyz`` ((H, W, 3) float, mm, NaN = no data).

    Infinite values are treated as an error, not as missing data, and so is a placeholder for no
    data (one exact point, such as (0, 0, 0) or -999999, at many pixels): ``.npz`` has no
    convention but NaN for no data, and a guessed one would silently keep a converter's real
    zeros or drop a scan's real points, so the user is asked for NaN.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected an .npz with key 'xyz')")
    check_numpy_file(path, "xyz")
    try:
        with np.load(path, allow_pickle=False) as data:
            if "xyz" not in data.files:
                raise InputError(path, f"key 'xyz' missing (found {sorted(data.files)})")
            xyz = data["xyz"]
    except InputError:
        raise
    except Exception as exc:  # zipfile / pickle / value errors from numpy
        raise InputError(path, f"cannot read as .npz: {exc}") from exc
    xyz = _check_xyz(xyz, f"{path}: key 'xyz'")
    if np.isinf(xyz).any():
        raise InputError(path, "key 'xyz': infinite values (use NaN for no data)")
    # a pixel is valid only when all three coordinates are
    xyz = xyz.copy()
    xyz[~np.all(np.isfinite(xyz), axis=-1)] = np.nan
    _check_placeholder(xyz, path, "key 'xyz'", "pixels", "use NaN for no data")
    return xyz


def write_npz_range(path: str | Path, xyz: np.ndarray) -> None:
    """Write a range image as ``.npz`` with key ``xyz`` (compressed)."""
    xyz = _check_xyz(xyz, path)
    with writing(path):
        np.savez_compressed(Path(path), xyz=xyz)


def read_range(path: str | Path) -> np.ndarray:
    """Read a range image by its suffix: ``.abs``, ``.abs.gz`` or ``.npz``.

    Returns
    -------
    xyz : (H, W, 3) float64, mm, NaN = no data.
    """
    name = Path(path).name.lower()
    if name.endswith(".abs") or name.endswith(".abs.gz"):
        return read_abs(path)
    if name.endswith(".npz"):
        return read_npz_range(path)
    raise InputError(path, "xyz: unknown range format (expected .abs, .abs.gz or .npz)")
