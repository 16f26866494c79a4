"""Loading one take's input files into arrays, with the cross-file checks."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import plane_spread
from scan2morph.io.calibration import StereoCalibration, read_stereo_calibration
from scan2morph.io.image import read_color
from scan2morph.io.landmarks import complete, read_pts
from scan2morph.io.range_image import read_range
from scan2morph.tol import MIN_FACE_RELIEF_MM, MIN_FACE_RELIEF_SHARE
from scan2morph.units import units_hint

#: Smallest range or colour image accepted, px (width and height).
MIN_IMAGE_PX = 16
#: Plausible 3D distance between the outer eye corners (iBUG 37 and 46) of a face, mm: adults
#: about 80-100, children less, and a point lifted onto a stereo reconstruction's hole edge a few
#: mm off (the real head's clicked stereo neutral: 69 mm against its annotation's 76); a wrong
#: unit is 10 times or more outside.
EYE_SPAN_MM = (50.0, 150.0)
#: A face whose outer eye corners are closer in the image than this share of the nose-bridge to
#: chin distance (iBUG 28 to 9) is seen from the side (frontal faces: about 0.8).
MIN_EYE_SPAN_RATIO = 0.3
#: The band a stereo take's texture shot is compared with its left image in: a difference of
#: Gaussians of standard deviations (fine, coarse), each the larger of a floor (px) and a share of
#: the image width (3 and 12 px at 640 px wide).
TEXTURE_SHOT_BAND = ((2.0, 3.0 / 640), (8.0, 12.0 / 640))
#: Least normalised correlation of a texture shot with its left image in that band.
MIN_TEXTURE_SHOT_CORRELATION = 0.6
#: Window (radius, px, and share of the image width) searched for range data at a landmark: the
#: smallest radius first, doubled up to the largest until it holds :data:`_LIFT_MIN_PIXELS`.
_LIFT_RADIUS = (2, 0.03)
#: Pixels with data a lifting window needs before it stops growing (a median robust to a spike).
_LIFT_MIN_PIXELS = 5
#: A nose tip this far (mm) behind the plane of the outer eye corners and the mouth, seen from the
#: scanner, is a mirrored frame; nearer the plane the test does not decide.
MIRROR_MARGIN_MM = 5.0
#: Most one outer eye corner's depth may be of the other's, in a camera's frame: the two lie on
#: one face (a head turned 60 degrees at 30 cm: 1.3), a corner on the background behind it (the
#: face displaced on the colour grid by a wrong depth scale, or landmarks of another view) lies
#: further.
MAX_EYE_DEPTH_RATIO = 1.5
#: Units a face-size error may come from: (name, factor to mm).
_UNITS = (("metres", 1000.0), ("cm", 10.0), ("inches", 25.4), ("0.1 mm", 0.1), ("µm", 1e-3))


def likely_unit(size: float, band: tuple[float, float]) -> str | None:
    """The unit a size read as mm is most likely in: of metres, cm, inches, 0.1 mm and µm, the
    one in which it would lie within ``band`` (mm), nearest the band's middle (geometric mean)
    when several do (a mesh 8.5 units across is a head in inches, 217 mm, sooner than in cm,
    85 mm); None when none does."""
    lo, hi = band
    fits = [
        (abs(np.log(size * f / np.sqrt(lo * hi))), name)
        for name, f in _UNITS
        if lo <= size * f <= hi
    ]
    return min(fits)[1] if fits else None


@dataclass(frozen=True)
class RangeTake:
    """A range take: XYZ, color and landmarks on the same pixel grid.

    Attributes
    ----------
    xyz : (H, W, 3) float64
        mm, NaN = no data, in the take's scanner frame.
    color : (H, W, 3) uint8 or None
        RGB, pixel to pixel with ``xyz``; None for a geometry-only scan.
    landmarks : (68, 2) float64 or None
        0-based pixel coordinates, NaN rows for points the file leaves out (a 51-point file's
        jawline); None when the take has no landmark file (they are detected).
    """

    xyz: np.ndarray
    color: np.ndarray | None
    landmarks: np.ndarray | None


def read_range_take(
    xyz_path: str | Path,
    color_path: str | Path | None,
    landmarks_path: str | Path | None,
    loaded: Mapping[str, np.ndarray] | None = None,
) -> RangeTake:
    """Read a range take and check that its files agree (``color_path`` None: a geometry-only
    scan, no colour image; ``landmarks_path`` None: no landmark file).

    ``loaded`` holds files already read by their readers (sheet column -> array: ``xyz``,
    ``color``, ``landmarks``), which are then not read again.

    Raises
    ------
    InputError
        From the readers, or when the color image's size differs from the range image's, or when
        the range image holds no data at all.
    """
    loaded = loaded or {}
    xyz = loaded["xyz"] if "xyz" in loaded else read_range(xyz_path)
    check_image_size(xyz.shape, xyz_path, "xyz")
    color = None
    if color_path is not None:
        color = loaded["color"] if "color" in loaded else read_color(color_path)
    if color is not None and color.shape[:2] != xyz.shape[:2]:
        raise InputError(
            color_path,
            f"color: image is {color.shape[1]}x{color.shape[0]} (WxH) but the range image "
            f"{Path(xyz_path).name} is {xyz.shape[1]}x{xyz.shape[0]}; they must be pixel to pixel",
        )
    if not np.isfinite(xyz).any():
        raise InputError(xyz_path, "xyz: no valid pixel in the range image")
    landmarks = _read_clicks(landmarks_path, loaded, xyz.shape[1], xyz.shape[0])
    return RangeTake(xyz=xyz, color=color, landmarks=landmarks)


def range_in_mm(
    scan: RangeTake, mm_per_unit: float, xyz_path: str | Path, landmarks_path: str | Path | None
) -> np.ndarray:
    """A range take's xyz in mm, scaled by the sheet's unit, (H, W, 3) float64; with a complete
    landmark file its face checked in mm (:func:`check_face`: a size error says what the sheet's
    ``units`` column did, :func:`~scan2morph.units.units_hint`). The ingest and the subject's
    check read a range take alike through it."""
    xyz = scan.xyz * mm_per_unit
    if complete(scan.landmarks):
        hint = units_hint(mm_per_unit)
        check_face(xyz, scan.landmarks, xyz_path, landmarks_path, unit_hint=hint)
    return xyz


def _read_clicks(
    path: str | Path | None, loaded: Mapping[str, np.ndarray], width: int, height: int
) -> np.ndarray | None:
    """A take's landmark file on its image (None without one), checked to lie on the image."""
    if path is None:
        return None
    landmarks = loaded["landmarks"] if "landmarks" in loaded else read_pts(path)
    check_landmarks_inside(landmarks, width, height, path)
    return landmarks


def check_landmarks_inside(
    landmarks: np.ndarray, width: int, height: int, source: str | Path
) -> None:
    """Check that landmarks lie on an image of ``width`` x ``height`` pixels.

    Parameters
    ----------
    landmarks : (n, 2) float
        0-based pixel coordinates ((0, 0) is the centre of the top-left pixel); a point may lie
        anywhere on a pixel, so the image spans ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
    width, height : int
        Image size, px.
    source : str or path-like
        The landmark file, named in the error.

    Raises
    ------
    InputError
        A point lies outside the image (names the first one, 1-based, and the count).
    """
    outside = (
        (landmarks[:, 0] < -0.5)
        | (landmarks[:, 0] > width - 0.5)
        | (landmarks[:, 1] < -0.5)
        | (landmarks[:, 1] > height - 0.5)
    )
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise InputError(
            source,
            f"point {k + 1} lies outside the {width}x{height} image "
            f"({int(outside.sum())} points outside)",
        )


@dataclass(frozen=True, eq=False)
class StereoTake:
    """A stereo take: the raw image pair, its calibration and the landmarks on the left image.

    Attributes
    ----------
    left, right : (H, W, 3) uint8
        RGB images of the left (first) and right (second) camera, raw (distorted).
    calib : StereoCalibration
        The rig, ``x_right = R x_left + T``, mm.
    landmarks : (68, 2) float64
        0-based pixel coordinates on the raw left image.
    color : (H, W, 3) uint8 or None
        The left camera's texture shot (the skin without the rig's projected pattern), when
        given; None: the left image is the take's colour.
    """

    left: np.ndarray
    right: np.ndarray
    calib: StereoCalibration
    landmarks: np.ndarray | None
    color: np.ndarray | None = None

    @property
    def texture(self) -> np.ndarray:
        """(H, W, 3) uint8: the take's colour on the left camera's grid, the texture shot if
        there is one, else the left image."""
        return self.left if self.color is None else self.color


def read_stereo_take(
    left_path: str | Path,
    right_path: str | Path,
    calibration_path: str | Path,
    landmarks_path: str | Path | None,
    color_path: str | Path | None = None,
) -> StereoTake:
    """Read a stereo take and check that its files agree.

    Parameters
    ----------
    left_path, right_path : str or path-like
        The raw images (PNG/PPM/JPEG) of the left (first) and right (second) camera.
    calibration_path : str or path-like
        OpenCV FileStorage YAML with ``K1 D1 K2 D2 R T`` (mm), see
        :func:`~scan2morph.io.read_stereo_calibration`.
    landmarks_path : str or path-like or None
        iBUG 68- (or 51-) point ``.pts`` on the raw left image; None: no landmark file.
    color_path : str or path-like or None
        The left camera's texture shot (PNG/PPM/JPEG; the same camera and size as the left image,
        taken without the rig's projected pattern); None: the left image is the take's colour.

    Returns
    -------
    StereoTake

    Raises
    ------
    InputError
        From the readers (a missing file, a calibration missing a matrix or with a wrong
        shape, a file that is not a calibration, a bad ``.pts``); the right image's size
        differs from the left's (names the right file); the calibration's
        ``image_width``/``image_height`` differ from the images', or a principal point lies
        outside them (names the calibration file); the right image is the left one; a landmark
        lies outside the left image (names the ``.pts`` file); the texture shot's size differs
        from the left image's, or it is not the left camera's view (:func:`check_texture_shot`,
        names the colour file).
    """
    left = read_color(left_path, "left")
    check_image_size(left.shape, left_path, "left")
    right = read_color(right_path, "right")
    h, w = left.shape[:2]
    _check_left_size(
        right, left, right_path, "right", Path(left_path).name,
        "the two images of a stereo pair must have the same size",
    )  # fmt: skip
    if np.array_equal(left, right):
        raise InputError(
            right_path,
            f"right: the same image as the left {Path(left_path).name} (one file given twice?); "
            "expected the second camera's view",
        )
    calib = read_stereo_calibration(calibration_path)
    if calib.image_size is not None and tuple(calib.image_size) != (w, h):
        raise InputError(
            calibration_path,
            f"image_width/image_height: {calib.image_size[0]}x{calib.image_size[1]} but the "
            f"images are {w}x{h} (WxH); is this the calibration of this camera pair?",
        )
    for name in ("K1", "K2"):
        cx, cy = getattr(calib, name)[:2, 2]
        if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
            raise InputError(
                calibration_path,
                f"{name}: the principal point ({cx:g}, {cy:g}) px lies outside the {w}x{h} "
                "images; is this the calibration of this camera pair, at this image size?",
            )
    landmarks = _read_clicks(landmarks_path, {}, w, h)
    color = None
    if color_path is not None:
        color = read_color(color_path)
        check_texture_shot(color, left, color_path, Path(left_path).name)
    return StereoTake(left=left, right=right, calib=calib, landmarks=landmarks, color=color)


def check_texture_shot(color: np.ndarray, left: np.ndarray, source, left_name: str) -> None:
    """Refuse a stereo take's texture shot that is not the left camera's view of the take.

    Both images are band-passed (a difference of Gaussians, :data:`TEXTURE_SHOT_BAND`: a
    projected pattern's fine dots and the lighting's slow change fall out, the face's features
    and outline stay) and compared pixel to pixel by their normalised correlation, which must
    reach :data:`MIN_TEXTURE_SHOT_CORRELATION`. Measured: a texture shot of the same exposure
    0.88-0.90 (the real head's and the synthetic faces', 160 x 120 to 640 x 480), the right
    camera's view of the face below 0.13, the mirrored view below 0.25, the shot of the next
    take (the head 5 mm and 3 degrees away, smiling) 0.55.

    Parameters
    ----------
    color, left : (H, W, 3) uint8
        The texture shot and the left image.
    source : str or path-like
        The texture shot's file, named in the error.
    left_name : str
        The left image's file name, for the message.

    Raises
    ------
    InputError
        The sizes differ, or the two do not correlate.
    """
    import cv2

    _check_left_size(
        color, left, source, "color", left_name,
        "a stereo take's colour is the left camera's texture shot, at the left image's size",
    )  # fmt: skip
    w = left.shape[1]
    fine, coarse = (max(lo, w * share) for lo, share in TEXTURE_SHOT_BAND)
    band = []
    for image in (left, color):
        grey = np.asarray(image, np.float32).mean(axis=2)
        b = cv2.GaussianBlur(grey, (0, 0), fine) - cv2.GaussianBlur(grey, (0, 0), coarse)
        band.append(b.astype(np.float64).ravel() - b.mean())
    norm = np.sqrt(np.dot(band[0], band[0]) * np.dot(band[1], band[1]))
    correlation = float(np.dot(band[0], band[1]) / norm) if norm > 0 else 0.0
    if correlation < MIN_TEXTURE_SHOT_CORRELATION:
        raise InputError(
            source,
            f"color: the image correlates with the left image {left_name} at {correlation:.2f} "
            f"(at least {MIN_TEXTURE_SHOT_CORRELATION:g} expected); a stereo take's colour is "
            "the left camera's texture shot of the same moment (not the right camera's, nor "
            "another take's)",
        )


def _check_left_size(
    image: np.ndarray, left: np.ndarray, source, field: str, left_name: str, why: str
) -> None:
    """Refuse a stereo take's ``field`` image (its file ``source``) whose size is not the left
    image's (``left_name``), saying ``why`` it must be."""
    (h, w), (hi, wi) = left.shape[:2], image.shape[:2]
    if (hi, wi) != (h, w):
        raise InputError(
            source,
            f"{field}: image is {wi}x{hi} (WxH) but the left image {left_name} is {w}x{h}; {why}",
        )


def check_image_size(shape: tuple[int, ...], source: str | Path, field: str) -> None:
    """Refuse an image smaller than :data:`MIN_IMAGE_PX` on a side (names ``source``)."""
    h, w = shape[:2]
    if min(h, w) < MIN_IMAGE_PX:
        raise InputError(
            source,
            f"{field}: the image is {w}x{h} px (WxH); a face scan needs at least "
            f"{MIN_IMAGE_PX}x{MIN_IMAGE_PX}",
        )


def lift_landmarks(xyz: np.ndarray, landmarks: np.ndarray, numbers) -> np.ndarray:
    """3D points of the range image at some landmarks: the per-coordinate median of the pixels
    with data around each (robust to a spike), in the smallest window of :data:`_LIFT_RADIUS`
    that holds :data:`_LIFT_MIN_PIXELS` of them (3% of the width, always, put an outer eye
    corner 11 mm inside a face far from the camera, at 2 mm per pixel).

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    landmarks : (68, 2) float, 0-based pixel coordinates
    numbers : sequence of int
        iBUG numbers (1-based) of the landmarks to lift.

    Returns
    -------
    (len(numbers), 3) float64, NaN for a landmark without data in its window.
    """
    h, w = xyz.shape[:2]
    largest = max(_LIFT_RADIUS[0], int(round(_LIFT_RADIUS[1] * w)))
    out = np.full((len(numbers), 3), np.nan)
    for i, n in enumerate(numbers):
        x, y = (int(round(v)) for v in landmarks[n - 1])
        r = _LIFT_RADIUS[0]
        while True:
            patch = xyz[max(y - r, 0) : y + r + 1, max(x - r, 0) : x + r + 1].reshape(-1, 3)
            patch = patch[np.isfinite(patch).all(axis=1)]
            if len(patch) >= _LIFT_MIN_PIXELS or r >= largest:
                break
            r = min(2 * r, largest)
        if len(patch):
            out[i] = np.median(patch, axis=0)
    return out


def flat_surface(points: np.ndarray) -> str | None:
    """Why a scan's surface is no face because it is flat (a board: no relief for a nose), or
    None.

    Parameters
    ----------
    points : (..., 3) float
        A range grid (H, W, 3) or a mesh's vertices (N, 3), mm, NaN = no data.

    Returns
    -------
    str or None
        ``no face relief: the surface is flat (...)``, naming its depth and width, when it is
        less than :data:`~scan2morph.tol.MIN_FACE_RELIEF_MM` deep and than
        :data:`~scan2morph.tol.MIN_FACE_RELIEF_SHARE` of its width.
    """
    depth, width = plane_spread(points)
    if depth >= MIN_FACE_RELIEF_MM or depth >= MIN_FACE_RELIEF_SHARE * width:
        return None
    return (
        f"no face relief: the surface is flat ({depth:.1f} mm deep about its best-fitting plane "
        f"over {width:.0f} mm across, 1st to 99th percentile; a face is at least "
        f"{MIN_FACE_RELIEF_MM:g} mm deep)"
    )


def _check_winding(lm: np.ndarray, source) -> None:
    """Refuse landmarks (68, 2) px mirrored left/right: the outer eye corners iBUG 37 -> 46
    and the chin 9 turn clockwise in the image (y down) on a face seen from the front.

    Raises
    ------
    InputError
        Naming ``source``; asking whether the file's x and y are swapped when the eyes lie
        one above the other (a file written row, column mirrors the face about its diagonal).
    """
    d1, d2 = lm[45] - lm[36], lm[8] - lm[36]
    if d1[0] * d2[1] - d1[1] * d2[0] > 0:
        return
    swapped = (
        "; the eyes lie one above the other: are the file's x and y swapped? (x is the column, "
        "y the row)"
        if abs(d1[1]) > abs(d1[0])
        else ""
    )
    raise InputError(
        source,
        "landmarks: mirrored left/right (the outer eye corners iBUG 37 -> 46 and the chin 9 "
        f"wind the wrong way; iBUG 37 is the outer corner of the eye on the image's left){swapped}",
    )


def check_face(
    xyz: np.ndarray,
    landmarks: np.ndarray,
    xyz_source: str | Path,
    landmarks_source: str | Path,
    unit_hint: str = "",
    eye_span_mm: tuple[float, float] = EYE_SPAN_MM,
    camera_frame: bool = False,
) -> float:
    """Check that the landmarks mark a plausible, roughly frontal face on range data in mm.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data (a range image, or a stereo reconstruction)
    landmarks : (68, 2) float, 0-based pixel coordinates on the same grid
    xyz_source : str or path-like
        Named in the size (unit) errors: the range file, or the stereo calibration.
    landmarks_source : str or path-like
        Named in the landmark errors: the ``.pts`` file.
    unit_hint : str
        Appended to a size error (e.g. what to check in a stereo calibration).
    eye_span_mm : (float, float)
        The outer eye corners' accepted 3D distance, mm (default :data:`EYE_SPAN_MM`).
    camera_frame : bool
        True when ``xyz`` is in a camera's frame (z the depth along its axis, as an RGB-D
        take's): the outer eye corners must then lie at depths within
        :data:`MAX_EYE_DEPTH_RATIO` of each other (one on the face and one on the background
        can be 50-150 mm apart too).

    Returns
    -------
    float
        The 3D distance between the outer eye corners (iBUG 37 and 46), mm.

    Raises
    ------
    InputError
        The landmarks all coincide; the outer eye corners are nearly coincident in the image
        against the nose-bridge to chin distance (a profile view); the landmarks are mirrored
        left/right (eye corners and chin wind the wrong way); an outer eye corner has no range
        data around it (landmarks on the background, or of another scan); the outer eye
        corners are not ``eye_span_mm`` (50-150 mm) apart in 3D (names the value and the unit
        it suggests); in a camera frame, one outer eye corner lies much deeper than the other;
        the surface is flat (:func:`flat_surface`: a board, a photo of a face).
    """
    lm = np.asarray(landmarks, dtype=np.float64)
    spread = float(np.ptp(lm, axis=0).max())
    if spread < 1.0:
        raise InputError(
            landmarks_source,
            f"landmarks: all 68 points coincide (within {spread:.2g} px at "
            f"{(lm.mean(axis=0) + 1).round(1).tolist()}, 1-based); expected points spread over a face",
        )
    eyes = float(np.linalg.norm(lm[45] - lm[36]))
    height = float(np.linalg.norm(lm[8] - lm[27]))
    if eyes < MIN_EYE_SPAN_RATIO * height:
        raise InputError(
            landmarks_source,
            f"head pose: the outer eye corners (iBUG 37, 46) are {eyes:.1f} px apart in the image "
            f"against {height:.1f} px from the nose bridge to the chin (iBUG 28, 9): a profile or "
            f"extreme head pose (expected a roughly frontal face, ratio >= {MIN_EYE_SPAN_RATIO:g})",
        )
    _check_winding(lm, landmarks_source)
    lifted = lift_landmarks(xyz, lm, (37, 46))
    for k, n in enumerate((37, 46)):
        if not np.isfinite(lifted[k]).all():
            raise InputError(
                landmarks_source,
                f"landmarks: iBUG {n} at {(lm[n - 1] + 1).round(1).tolist()} (1-based px) lies "
                "where the range image has no data: are the landmarks on the face and of this "
                "scan?",
            )
    span = float(np.linalg.norm(lifted[1] - lifted[0]))
    lo, hi = eye_span_mm
    if not lo <= span <= hi:
        unit = likely_unit(span, eye_span_mm)
        if unit is not None:
            likely = f"the coordinates look like {unit}, not mm"
        elif span > 0:
            likely = f"a face {span / 100.0:.2g} times the usual size"
        else:
            likely = "no extent at all"
        raise InputError(
            xyz_source,
            f"face size: the outer eye corners (iBUG 37, 46) are {span:.4g} mm apart in 3D, "
            f"expected {lo:g}-{hi:g} mm ({likely}){unit_hint}",
        )
    if camera_frame:
        _check_eye_depths(lifted, landmarks_source)
    if flat := flat_surface(np.asarray(xyz)[::4, ::4]):  # every 4th pixel: the spread is the same
        raise InputError(
            xyz_source, f"{flat}, though its landmarks mark a face: expected a scan of a face"
        )
    return span


def _check_eye_depths(lifted: np.ndarray, source: str | Path) -> None:
    """Refuse outer eye corners (``lifted``, (2, 3) mm in a camera's frame) of which one lies
    more than :data:`MAX_EYE_DEPTH_RATIO` times as deep as the other (names ``source``, the
    landmark file)."""
    near, far = sorted(lifted[:, 2])
    if near > 0 and far > MAX_EYE_DEPTH_RATIO * near:
        raise InputError(
            source,
            f"landmarks: the outer eye corners (iBUG 37, 46) lie at depths {lifted[0, 2]:.4g} "
            f"and {lifted[1, 2]:.4g} mm, not on one face (at most {MAX_EYE_DEPTH_RATIO:g} times "
            "as deep as each other expected): are the landmarks on the face and of this scan?",
        )


def check_handedness(xyz: np.ndarray, landmarks: np.ndarray, source: str | Path) -> float:
    """Refuse a take whose XYZ is in a mirrored (left-handed) frame.

    The pixel grid (x right, y down) and the direction the scanner looks along form a
    right-handed frame with any right-handed scanner frame. So in the plane of the outer eye
    corners and the mouth (iBUG 37, 46 and the mean of 49 and 55), oriented by the image's
    winding of those points, the nose tip (iBUG 31) lies on the scanner's side. In a mirrored
    frame (two axes swapped, or one negated, as a wrong export gives) it lies behind the face.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    landmarks : (68, 2) float, 0-based pixel coordinates on the same grid
    source : str or path-like
        Named in the error (the take's XYZ file).

    Returns
    -------
    float
        The nose tip's signed distance from that plane, mm (negative: towards the scanner);
        NaN when a point has no data (the test is skipped).

    Raises
    ------
    InputError
        The nose tip lies more than :data:`MIRROR_MARGIN_MM` behind the plane.
    """
    eye_r, eye_l, mouth_r, mouth_l, nose = lift_landmarks(xyz, landmarks, (37, 46, 49, 55, 31))
    mouth = (mouth_r + mouth_l) / 2
    normal = np.cross(eye_l - eye_r, mouth - eye_r)
    length = float(np.linalg.norm(normal))
    if not length > 0:  # no data at a point (NaN), or the points in a line
        return float("nan")
    depth = float(np.dot(nose - eye_r, normal) / length)
    if np.isfinite(depth) and depth > MIRROR_MARGIN_MM:
        raise InputError(
            source,
            f"xyz: a mirrored (left-handed) frame: the nose tip (iBUG 31) lies {depth:.1f} mm "
            "behind the plane of the eye corners and the mouth as the scanner sees them; expected "
            "a right-handed frame (were two axes swapped or one negated on export?)",
        )
    return depth
