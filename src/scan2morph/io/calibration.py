"""Stereo rig calibration: read, check and write OpenCV FileStorage YAML files.

The file holds the matrices of :func:`cv2.stereoCalibrate`'s convention, in mm::

    %YAML:1.0
    ---
    K1: !!opencv-matrix   # 3x3 camera matrix of the left (first) camera, px
    D1: !!opencv-matrix   # its distortion coefficients (4, 5, 8, 12 or 14 values)
    K2, D2                # the same for the right (second) camera
    R: !!opencv-matrix    # 3x3 rotation and
    T: !!opencv-matrix    # 3 translation (mm): x2 = R @ x1 + T maps left-camera points
                          # into the right camera's frame
    image_width: 640      # optional, px
    image_height: 480     # optional, px

OpenCV's own sample calibration files name the camera matrices ``M1``/``M2``; they are read
as ``K1``/``K2``. Matrices may also be plain YAML sequences (flat or nested). PyYAML cannot
read these files (it rejects the ``%YAML:1.0`` header), so both directions use
:class:`cv2.FileStorage`.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError, OutputError, no_space_left, writing

#: Largest ``max|R^T R - I|`` accepted for the rig rotation (files written with ~6 digits pass).
ROTATION_TOL = 1e-4
#: Smallest accepted baseline |T|, mm: a smaller one means T is not in mm (metres?) or is zero.
MIN_BASELINE_MM = 1.0
#: Numbers of distortion coefficients OpenCV's camera model accepts.
N_DISTORTION = (4, 5, 8, 12, 14)

# Accepted names per field, first one preferred (M1/M2 are OpenCV's sample names).
_KEYS = {
    "K1": ("K1", "M1"),
    "D1": ("D1",),
    "K2": ("K2", "M2"),
    "D2": ("D2",),
    "R": ("R",),
    "T": ("T",),
}


@dataclass(frozen=True, eq=False)
class StereoCalibration:
    """Intrinsics and extrinsics of a calibrated stereo pair (OpenCV's camera model).

    Parameters
    ----------
    K1, K2 : (3, 3) float64
        Camera matrices of the left (first) and right (second) camera, px.
    D1, D2 : (n,) float64
        Distortion coefficients, n in 4, 5, 8, 12, 14 (OpenCV's order k1 k2 p1 p2 [k3 ...]).
    R : (3, 3) float64
        Rotation from the left camera frame to the right camera frame.
    T : (3,) float64
        Translation, mm: a point ``x1`` in the left camera frame is ``R @ x1 + T`` in the
        right camera frame. A (3, 1) input is flattened.
    image_size : (int, int) or None
        ``(width, height)`` in px of the images the calibration belongs to, if known.

    Notes
    -----
    The constructor only converts to float64 arrays; :func:`validate_stereo_calibration`
    checks shapes and values and names the source in its errors.
    """

    K1: np.ndarray
    D1: np.ndarray
    K2: np.ndarray
    D2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    image_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        for name in ("K1", "K2", "R"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        for name in ("D1", "D2", "T"):
            object.__setattr__(
                self, name, np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            )
        if self.image_size is not None:
            object.__setattr__(self, "image_size", tuple(int(v) for v in self.image_size))

    @property
    def baseline_mm(self) -> float:
        """Distance between the two camera centres, mm."""
        return float(np.linalg.norm(self.T))


def validate_stereo_calibration(
    calib: StereoCalibration, source: str | PathLike[str]
) -> StereoCalibration:
    """Check the shapes and values of a stereo calibration.

    Parameters
    ----------
    calib : StereoCalibration
        The calibration to check.
    source : str or path-like
        The file (or label) it came from, named in the errors.

    Returns
    -------
    StereoCalibration
        ``calib`` itself, so that the call can be chained.

    Raises
    ------
    InputError
        A camera matrix that is not 3x3 with positive focal lengths and last row (0, 0, 1);
        distortion coefficients not 4, 5, 8, 12 or 14 values; R not a 3x3 rotation; T not 3
        values or a baseline below :data:`MIN_BASELINE_MM`; a non-finite value; a non-positive
        image size.
    """
    for name in ("K1", "K2"):
        K = getattr(calib, name)
        _check_finite(K, name, source)
        if K.shape != (3, 3):
            raise InputError(source, f"{name}: expected a 3x3 camera matrix, got shape {K.shape}")
        if not np.allclose(K[2], (0.0, 0.0, 1.0), atol=1e-9, rtol=0.0):
            raise InputError(source, f"{name}: last row must be (0, 0, 1), got {K[2].tolist()}")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise InputError(
                source, f"{name}: focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}"
            )
    for name in ("D1", "D2"):
        D = getattr(calib, name)
        _check_finite(D, name, source)
        if D.size not in N_DISTORTION:
            raise InputError(
                source,
                f"{name}: expected 4, 5, 8, 12 or 14 distortion coefficients, got {D.size}",
            )
    _check_finite(calib.R, "R", source)
    if calib.R.shape != (3, 3):
        raise InputError(source, f"R: expected a 3x3 rotation matrix, got shape {calib.R.shape}")
    orth = float(np.abs(calib.R.T @ calib.R - np.eye(3)).max())
    det = float(np.linalg.det(calib.R))
    if orth > ROTATION_TOL or det <= 0:
        raise InputError(
            source,
            f"R: not a rotation matrix (max|R^T R - I| = {orth:.3g}, tolerance {ROTATION_TOL:g}; "
            f"det = {det:.6g}, expected +1)",
        )
    _check_finite(calib.T, "T", source)
    if calib.T.shape != (3,):
        raise InputError(source, f"T: expected 3 values (mm), got {calib.T.size}")
    if calib.baseline_mm < MIN_BASELINE_MM:
        raise InputError(
            source,
            f"T: baseline |T| = {calib.baseline_mm:.6g} is below {MIN_BASELINE_MM:g} mm; "
            "T must be in mm (is it in metres?)",
        )
    if calib.image_size is not None:
        if len(calib.image_size) != 2 or min(calib.image_size) <= 0:
            raise InputError(
                source,
                f"image_width/image_height: expected two positive sizes, got {calib.image_size}",
            )
    return calib


def read_stereo_calibration(path: str | PathLike[str]) -> StereoCalibration:
    """Read a stereo calibration from an OpenCV FileStorage YAML (or XML/JSON) file.

    Parameters
    ----------
    path : str or path-like
        The file. Keys ``K1 D1 K2 D2 R T`` (``M1``/``M2`` accepted for ``K1``/``K2``),
        optional ``image_width`` and ``image_height`` (px). T is in mm.

    Returns
    -------
    StereoCalibration
        The checked calibration, T as (3,) mm.

    Raises
    ------
    InputError
        Missing file; a file that FileStorage cannot parse or whose top level is not a map;
        a key given twice, a missing or malformed matrix (names the key); any check of
        :func:`validate_stereo_calibration`.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected an OpenCV FileStorage stereo calibration)")
    not_calibration = (
        "not an OpenCV FileStorage calibration (expected a YAML file with a '%YAML:1.0' header "
        "and the matrices K1 D1 K2 D2 R T)"
    )
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # the binding wraps parse errors in SystemError
        raise InputError(path, not_calibration + _yaml_text_hint(path)) from exc
    try:
        root = fs.root()
        if not fs.isOpened() or not root.isMap():
            raise InputError(path, not_calibration + _yaml_text_hint(path))
        keys = root.keys()
        if twice := next((k for k in keys if keys.count(k) > 1), None):  # OpenCV keeps the first
            raise InputError(path, f"{twice}: given twice; keep one value")
        values = {}
        for field, names in _KEYS.items():
            name = next((n for n in names if n in keys), None)
            if name is None:
                found = ", ".join(keys) if keys else "none"
                raise InputError(
                    path,
                    f"{field}: missing (keys {' or '.join(names)}; keys found: {found}); "
                    "is this a stereo calibration file?",
                )
            values[field] = _node_array(fs.getNode(name), name, path)
        image_size = _read_image_size(fs, keys, path)
    finally:
        fs.release()
    for name in ("K1", "K2", "R"):
        if values[name].shape != (3, 3) and values[name].size == 9 and values[name].ndim == 1:
            values[name] = values[name].reshape(3, 3)  # a flat sequence, row-major
    for name in ("D1", "D2", "T"):
        arr = values[name]
        # A (1, n) or (n, 1) matrix is a vector; anything else keeps its shape for the error.
        if arr.ndim == 2 and 1 in arr.shape:
            values[name] = arr.reshape(-1)
        elif arr.ndim != 1:
            what = "distortion coefficients" if name != "T" else "3 values (mm)"
            raise InputError(path, f"{name}: expected {what}, got a matrix of shape {arr.shape}")
    calib = StereoCalibration(**values, image_size=image_size)
    return validate_stereo_calibration(calib, path)


def write_stereo_calibration(path: str | PathLike[str], calib: StereoCalibration) -> None:
    """Write a stereo calibration as an OpenCV FileStorage YAML file (``%YAML:1.0`` header).

    Parameters
    ----------
    path : str or path-like
        The output file; its parent directory must exist.
    calib : StereoCalibration
        The calibration; checked first (errors name ``path``).

    Raises
    ------
    InputError
        ``calib`` fails :func:`validate_stereo_calibration`.
    OutputError
        The disk is full.
    OSError
        The file cannot be opened for writing.
    """
    path = Path(path)
    validate_stereo_calibration(calib, path)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML_1_0)
    if not fs.isOpened():
        if no_space_left(path, 4096):
            raise OutputError(path)
        raise OSError(f"{path}: cannot open for writing")
    with writing(path):
        _write_fields(fs, calib)


def _write_fields(fs: cv2.FileStorage, calib: StereoCalibration) -> None:
    try:
        fs.writeComment("Stereo calibration (cv2.stereoCalibrate convention): x2 = R x1 + T, mm")
        fs.write("K1", calib.K1)
        fs.write("D1", calib.D1.reshape(1, -1))
        fs.write("K2", calib.K2)
        fs.write("D2", calib.D2.reshape(1, -1))
        fs.write("R", calib.R)
        fs.write("T", calib.T.reshape(3, 1))
        if calib.image_size is not None:
            fs.write("image_width", int(calib.image_size[0]))
            fs.write("image_height", int(calib.image_size[1]))
    finally:
        fs.release()


def _node_array(node: cv2.FileNode, name: str, path: Path) -> np.ndarray:
    """A FileStorage node (``!!opencv-matrix`` or a flat/nested sequence) as float64."""
    if node.isMap():
        try:
            mat = node.mat()
        except cv2.error as exc:
            raise InputError(path, f"{name}: {_matrix_problem(node)}") from exc
        if mat is None:
            raise InputError(path, f"{name}: empty matrix")
        return np.asarray(mat, dtype=np.float64)
    if node.isSeq():
        rows = [node.at(i) for i in range(node.size())]
        if rows and all(r.isSeq() for r in rows):
            lengths = {r.size() for r in rows}
            if len(lengths) != 1:
                raise InputError(path, f"{name}: rows of different lengths {sorted(lengths)}")
            return np.array(
                [[_node_number(r.at(j), name, path) for j in range(r.size())] for r in rows]
            )
        return np.array([_node_number(r, name, path) for r in rows], dtype=np.float64)
    if node.isReal() or node.isInt():
        return np.array([node.real()], dtype=np.float64)
    raise InputError(path, f"{name}: expected a matrix or a sequence of numbers")


def _yaml_text_hint(path: Path) -> str:
    """What in a YAML file's text OpenCV's parser refuses without saying: a byte-order mark (as
    Windows editors save) or a tab in a line's indentation."""
    with open(path, "rb") as fh:
        raw = fh.read(1 << 20)  # a calibration is a few kB
    if raw.startswith(b"\xef\xbb\xbf"):
        return "; it starts with a byte-order mark (BOM): save it as UTF-8 without BOM"
    lines = raw.splitlines()
    tab = next((k for k, ln in enumerate(lines) if b"\t" in ln[: len(ln) - len(ln.lstrip())]), None)
    return "" if tab is None else f"; line {tab + 1} is indented with a tab (YAML: spaces only)"


def _matrix_problem(node: cv2.FileNode) -> str:
    """Why an ``!!opencv-matrix`` node does not read: a key missing, a non-numeric entry or a
    count of numbers other than rows x cols."""
    need = "expected an !!opencv-matrix with rows, cols, dt and rows x cols numbers in data"
    if missing := [k for k in ("rows", "cols", "dt", "data") if k not in node.keys()]:
        truncated = " (a truncated file?)" if "data" in missing else ""
        return f"{need}; {', '.join(missing)} missing{truncated}"
    data = node.getNode("data")
    entries = [data.at(i) for i in range(data.size())] if data.isSeq() else [data]
    if text := [e.string() for e in entries if not (e.isReal() or e.isInt())]:
        return f"{need}; got the non-numeric entry {text[0][:20]!r}"
    rows, cols = node.getNode("rows").real(), node.getNode("cols").real()
    return f"{need}; got rows {rows:g} x cols {cols:g} but {len(entries)} numbers"


def _node_number(node: cv2.FileNode, name: str, path: Path) -> float:
    if not (node.isReal() or node.isInt()):
        raise InputError(path, f"{name}: expected numbers, found a non-numeric entry")
    return float(node.real())


def _read_image_size(
    fs: cv2.FileStorage, keys: tuple[str, ...], path: Path
) -> tuple[int, int] | None:
    present = [k for k in ("image_width", "image_height") if k in keys]
    if not present:
        return None
    if len(present) == 1:
        missing = "image_height" if present[0] == "image_width" else "image_width"
        raise InputError(
            path, f"{missing}: missing while {present[0]} is given (give both or neither)"
        )
    size = []
    for key in ("image_width", "image_height"):
        node = fs.getNode(key)
        value = node.real() if (node.isInt() or node.isReal()) else float("nan")
        if not (np.isfinite(value) and value == int(value) and value > 0):
            raise InputError(path, f"{key}: expected a positive integer (px)")
        size.append(int(value))
    return size[0], size[1]


def _check_finite(arr: np.ndarray, name: str, source: str | PathLike[str]) -> None:
    if not np.all(np.isfinite(arr)):
        raise InputError(source, f"{name}: contains non-finite values (NaN or inf)")


__all__ = [
    "MIN_BASELINE_MM",
    "N_DISTORTION",
    "ROTATION_TOL",
    "StereoCalibration",
    "read_stereo_calibration",
    "validate_stereo_calibration",
    "write_stereo_calibration",
]
