"""Depth images: one frame (a 16-bit PNG, ``.npy`` or ``.npz``) or several frames of one take.

A take's ``depth`` may name several frames of the same pose: files separated by ``;``, or a
folder (its ``.png``/``.npy``/``.npz`` files in name order). The first frame is the one the
colour image was taken with (:mod:`scan2morph.io.rgbd`, :mod:`scan2morph.scan.fusion`).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.sheet import split_paths

#: Depth file suffixes.
DEPTH_SUFFIXES = (".png", ".npy", ".npz")


def depth_frame_paths(value) -> list[Path]:
    """The depth frames a take's ``depth`` names (module docstring), in order.

    Parameters
    ----------
    value : str, path-like or sequence of them
        One file, files separated by ``;``, a folder, or a sequence of these.

    Returns
    -------
    list of Path

    Raises
    ------
    InputError
        A folder without depth files, or nothing named.
    """
    if isinstance(value, str):
        parts = split_paths(value)
    elif isinstance(value, Path):
        parts = [value]
    else:
        parts = list(value)
    out: list[Path] = []
    for part in (str(p).strip() for p in parts):
        if not part:
            continue
        path = Path(part)
        if path.is_dir():
            found = sorted(f for f in path.iterdir() if f.suffix.lower() in DEPTH_SUFFIXES)
            if not found:
                raise InputError(
                    path, f"depth: the folder holds no depth frames (files {DEPTH_SUFFIXES})"
                )
            out.extend(found)
        else:
            out.append(path)
    if not out:
        raise InputError(str(value), "depth: no depth file named")
    return out


def read_depth_frames(value) -> list[np.ndarray]:
    """Read every depth frame a take's ``depth`` names (:func:`depth_frame_paths`) with
    :func:`read_depth`; frames of one take must have one size.

    Returns
    -------
    list of (H, W) float64
        Depth units, in the frames' order.

    Raises
    ------
    InputError
        From :func:`depth_frame_paths` and :func:`read_depth`; a frame whose size differs from
        the first's (names both).
    """
    paths = depth_frame_paths(value)
    frames = [read_depth(p) for p in paths]
    for path, frame in zip(paths[1:], frames[1:], strict=True):
        if frame.shape != frames[0].shape:
            raise InputError(
                path,
                f"depth: {frame.shape[1]}x{frame.shape[0]} px but the take's first frame "
                f"{paths[0].name} is {frames[0].shape[1]}x{frames[0].shape[0]} (WxH)",
            )
    return frames


def read_depth(path: str | Path) -> np.ndarray:
    """Read a depth image in depth units: a 16-bit PNG, an ``.npy`` or an ``.npz`` with ``depth``.

    Returns
    -------
    (H, W) float64
        Depth units (multiply by ``depth_scale_mm``); 0 and NaN = no data.

    Raises
    ------
    InputError
        Missing or unreadable file, an 8-bit or colour PNG, an array that is not 2D, negative
        or infinite values.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected a 16-bit depth PNG, .npy or .npz)")
    suffix = path.suffix.lower()
    if suffix not in DEPTH_SUFFIXES:
        raise InputError(path, f"depth: unknown format {suffix!r} (expected {DEPTH_SUFFIXES})")
    if suffix == ".png":
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise InputError(path, "depth: cannot decode the PNG (corrupt or not an image)")
        if img.ndim != 2 or img.dtype != np.uint16:
            kind = f"{img.dtype} with {1 if img.ndim == 2 else img.shape[2]} channels"
            raise InputError(path, f"depth: expected a 16-bit single-channel PNG, got {kind}")
        depth = img.astype(np.float64)
    else:
        try:
            if suffix == ".npz":
                with np.load(path, allow_pickle=False) as data:
                    if "depth" not in data.files:
                        raise InputError(path, f"key 'depth' missing (found {sorted(data.files)})")
                    depth = np.asarray(data["depth"])
            else:
                depth = np.asarray(np.load(path, allow_pickle=False))
        except InputError:
            raise
        except Exception as exc:  # zip, pickle or format errors from numpy
            raise InputError(path, f"depth: cannot read as {suffix}: {exc}") from None
        if depth.ndim != 2 or not np.issubdtype(depth.dtype, np.number):
            got = f"{depth.shape} {depth.dtype}"
            raise InputError(path, f"depth: expected an (H, W) number array, got {got}")
        depth = depth.astype(np.float64)
    if np.isinf(depth).any() or (depth < 0).any():
        raise InputError(path, "depth: negative or infinite values (0 or NaN = no data)")
    return depth


def write_depth_png(path: str | Path, depth_units: np.ndarray) -> None:
    """Write depth units (H, W) as a 16-bit PNG (values rounded, clipped to 0..65535)."""
    from scan2morph.errors import writing

    img = np.clip(np.rint(np.nan_to_num(depth_units, nan=0.0)), 0, 65535).astype(np.uint16)
    with writing(path):
        ok = cv2.imwrite(str(path), img)
    if not ok:
        raise InputError(path, "depth: could not write the PNG")


__all__ = [
    "DEPTH_SUFFIXES",
    "depth_frame_paths",
    "read_depth",
    "read_depth_frames",
    "write_depth_png",
]
