"""Color images (PNG, PPM, JPEG) as (H, W, 3) uint8 RGB arrays."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np

from scan2morph.errors import InputError, writing
from scan2morph.jobs import atomic_output

log = logging.getLogger("scan2morph")

COLOR_SUFFIXES = (".png", ".ppm", ".pnm", ".jpg", ".jpeg")


def read_color(path: str | Path, field: str = "color") -> np.ndarray:
    """Read a color image.

    Parameters
    ----------
    path : str or Path
    field : str
        The sheet column that names the file, for messages (``color``, ``left``, ``right``,
        ``texture``).

    Returns
    -------
    color : (H, W, 3) uint8
        RGB. Grey images are expanded to three channels; 16-bit images are scaled to 8 bit;
        alpha is dropped.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected a PNG/PPM/JPEG color image)")
    if path.suffix.lower() not in COLOR_SUFFIXES:
        raise InputError(
            path, f"{field}: unknown image format {path.suffix!r} (expected PNG, PPM or JPEG)"
        )
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(path, f"{field}: cannot decode the image (corrupt or not an image)")
    if path.suffix.lower() in (".jpg", ".jpeg"):
        _check_whole_jpeg(path, field)
        _warn_exif_turn(path, field)
    if img.dtype == np.uint16:
        img = (img / 257.0).round().astype(np.uint8)
    if img.dtype != np.uint8:
        raise InputError(
            path, f"{field}: unsupported pixel type {img.dtype} (expected 8 or 16 bit)"
        )
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    elif img.shape[2] == 4:
        img = img[:, :, :3]
    return np.ascontiguousarray(img[:, :, ::-1])


#: What a photo viewer does to a JPEG of each EXIF orientation (tag 274) other than 1.
EXIF_TURNS = {
    2: "mirrored left to right",
    3: "turned 180 degrees",
    4: "mirrored top to bottom",
    5: "mirrored about its top-left to bottom-right diagonal",
    6: "turned 90 degrees clockwise",
    7: "mirrored about its top-right to bottom-left diagonal",
    8: "turned 90 degrees anticlockwise",
}


def _warn_exif_turn(path: Path, field: str) -> None:
    """Warn of a JPEG whose EXIF orientation asks viewers to turn or mirror it (a phone's
    photo): its pixels are read as stored, so landmarks clicked in such a viewer, and a range
    grid made from the turned view, are in another pixel order."""
    import warnings

    from PIL import Image

    try:  # a photo of more pixels than Pillow's bomb limit reads in OpenCV: not a traceback
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as image:
                turn = EXIF_TURNS.get(image.getexif().get(274, 1))
    except (OSError, Image.DecompressionBombError):
        return
    if turn:
        log.warning(
            "%s: %s: the JPEG's EXIF orientation has viewers show it %s; its pixels are read "
            "as stored, not turned: landmarks and UVs must be in the stored pixel order",
            path,
            field,
            turn,
        )


def _check_whole_jpeg(path: Path, field: str) -> None:
    """Refuse a JPEG cut short: OpenCV decodes one without an error, the rows it lacks filled
    grey (Pillow's decoder says it is truncated; the pixels stay OpenCV's). A file ending in
    JPEG's end-of-image marker is whole and not decoded again.

    Raises
    ------
    InputError
        The file is a JPEG cut short.
    """
    with open(path, "rb") as fh:
        fh.seek(max(path.stat().st_size - 2, 0))
        if fh.read() == b"\xff\xd9":
            return
    from PIL import Image

    try:
        with Image.open(path) as image:
            image.load()
    except Image.DecompressionBombError:  # OpenCV decoded it: Pillow's limits are not ours
        return
    except OSError as exc:
        if "truncated" not in str(exc):  # OpenCV decoded it: Pillow's other limits are not ours
            return
        raise InputError(
            path,
            f"{field}: the image is cut short (a truncated copy or download: its last rows are "
            "missing); expected a whole JPEG",
        ) from None


def write_color(path: str | Path, color: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 RGB image; the format follows the suffix."""
    color = np.asarray(color)
    if color.ndim != 3 or color.shape[2] != 3 or color.dtype != np.uint8:
        raise InputError(path, f"color: expected (H, W, 3) uint8, got {color.shape} {color.dtype}")
    try:
        ok, data = cv2.imencode(Path(path).suffix, np.ascontiguousarray(color[:, :, ::-1]))
    except cv2.error:
        ok = False
    if not ok:
        raise InputError(
            path,
            f"color: cannot encode an image as {Path(path).suffix!r} (expected .png, .jpg, ...)",
        )
    # OpenCV's own writer cannot tell a full disk from a bad path
    with atomic_output(path) as tmp, writing(path):
        tmp.write_bytes(data.tobytes())
