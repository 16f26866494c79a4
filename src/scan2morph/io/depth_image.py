"""Depth images: one frame (a 16-bit PNG, ``.npy`` or ``.npz``) or several frames of one take.

A take's ``depth`` may name several frames of the same pose: files separated by ``;``, or a
folder (its ``.png``/``.npy``/``.npz`` files in name order, hidden ones, ``.name``, left out).
The first frame is the one the colour image was taken with (:mod:`scan2morph.io.rgbd`,
:mod:`scan2morph.scan.fusion`).
"""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.numpy_file import check_numpy_file
from scan2morph.sheet import split_paths

log = logging.getLogger("scan2morph")

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
            found = sorted(f for f in path.iterdir() if _frame_name(f.name))
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


def _frame_name(name: str) -> bool:
    """Whether a file of a depth folder is a frame: a depth suffix, and not hidden (macOS
    writes a ``._`` copy of each file's metadata beside it on a USB stick or a network share,
    with the file's own suffix)."""
    return Path(name).suffix.lower() in DEPTH_SUFFIXES and not name.startswith(".")


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
        check_numpy_file(path, "depth")
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
        _check_depth_type(depth.dtype, path)
        depth = depth.astype(np.float64)
    if np.isinf(depth).any() or (depth < 0).any():
        raise InputError(path, "depth: negative or infinite values (0 or NaN = no data)")
    return depth


def _check_depth_type(dtype: np.dtype, path: Path) -> None:
    """Refuse an 8-bit depth array (256 levels, as an 8-bit PNG is refused) and warn of a
    float16 one (11 significant bits: 0.5-1 mm steps at 1 m, in mm or in metres).

    Raises
    ------
    InputError
        An 8-bit integer array.
    """
    if dtype.itemsize == 1:
        raise InputError(
            path, f"depth: expected 16-bit or wider integers or float32/float64, got {dtype}"
        )
    if dtype == np.float16:
        log.warning(
            "%s: depth: float16 values keep 11 significant bits (steps of 1/2048 to 1/1024 of "
            "the value, 0.5-1 mm at 1 m): the surface is read quantised; save the depth as "
            "float32 or 16-bit integers",
            path,
        )


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


#: Depths at which a depth camera sees a face it can be detected in, mm (the nearest object's
#: median depth; beyond 4 m a face is under 0.4 px per mm for a colour camera of a 60-degree
#: field of view, too small to detect): outside them a depth scale off by 10 or 1000 is named.
FACE_DEPTH_MM = (150.0, 4000.0)
#: The nearest object: the points this far behind the nearest (1st percentile) depth, mm.
NEAREST_OBJECT_MM = 200.0


def check_face_depth(depth: np.ndarray, depth_scale_mm: float, intrinsics: str | Path) -> None:
    """Refuse a depth image whose nearest object lies where no face is detected, when the depth
    scale times 0.1, 10, 0.001 or 1000 puts it at a face's depth (:data:`FACE_DEPTH_MM`).

    For takes without a landmark file (with one, the landmarks' face size names the scale):
    the repair, whose thresholds are in mm, would otherwise cut the face apart and the
    detector refuse it for another reason (a "profile view").

    Parameters
    ----------
    depth : (H, W) array
        Depth along the camera's axis in the image's units (NaN or 0 = no data).
    depth_scale_mm : float
        The intrinsics' ``depth_scale_mm``: mm per unit.
    intrinsics : str or path-like
        The intrinsics file, named in the error.

    Raises
    ------
    InputError
        ``depth_scale_mm: ...`` with the scale that puts the face at a face's depth.
    """
    z = np.asarray(depth, dtype=np.float64)[::4, ::4] * depth_scale_mm
    z = z[np.isfinite(z) & (z > 0)]
    if len(z) == 0:
        return
    near = float(np.percentile(z, 1))
    depth = float(np.median(z[z < near + NEAREST_OBJECT_MM]))
    lo, hi = FACE_DEPTH_MM
    fits = [f for f in (0.1, 10.0, 0.001, 1000.0) if lo <= depth * f <= hi]
    if lo <= depth <= hi or not fits:
        return
    raise InputError(
        intrinsics,
        f"depth_scale_mm: {depth_scale_mm:g} puts the nearest object {depth:.0f} mm from the "
        f"camera (a face is detected {lo:g}-{hi:g} mm away); with depth_scale_mm = "
        f"{depth_scale_mm * fits[0]:g} (x {fits[0]:g}) it is {depth * fits[0]:.0f} mm away: is "
        "the depth scale in mm per unit?",
    )
