"""Finding the face in a range grid: its nose tip, scale and turn, and the refusals.

The nose tip is the surface's sharpest peak towards the camera: the point that stands out of the
smoothed surface in every direction (its depth compared with the depth ``PEAK_MM`` away in eight
directions, the smallest of the eight differences is its height). Its depth and the grid's
camera (:mod:`scan2morph.landmarks.camera`) give the face's scale in px per mm, so no image
face detector is needed. A second peak of a comparable height farther than
``OTHER_FACE_MM`` from the first is a second face. The face's turn (yaw) is the normal of the
plane fitted to the surface between ``PLANE_MM`` of the nose tip.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.take import flat_surface
from scan2morph.landmarks.camera import GridCamera, grid_camera

#: Distance of the eight depth probes around a nose-tip candidate, mm.
PEAK_MM = 22.0
#: Least height of a nose tip above its surroundings in every direction, mm.
MIN_PEAK_MM = 6.0
#: Least number of the eight probes around a peak that meet data.
MIN_PROBES = 5
#: A peak this far (3D) from the nose tip, at least SECOND_SHARE as high, is another face, mm.
OTHER_FACE_MM = 140.0
SECOND_SHARE = 0.6
#: The plane of the face: surface points between these distances of the nose tip, mm.
PLANE_MM = (35.0, 75.0)
#: The nose tip: the point nearest the camera within this of the peak, mm.
TIP_MM = 20.0
#: Largest yaw (turn about the vertical) the detector handles, degrees, as the face plane
#: measures it (it reads about 2/3 of the true turn of a head: 22 at 30, 26 at 50 degrees).
MAX_YAW_DEG = 25.0
#: Smallest face handled: px per mm at the nose tip (about 36 px between the outer eye corners).
MIN_PX_PER_MM = 0.4
#: The scale of the peak search is that of the surface this deep behind the nearest point, mm.
HEAD_DEPTH_MM = 200.0
#: Least number of pixels with data for a face.
MIN_PIXELS = 400


@dataclass(frozen=True)
class Face:
    """Where the face is in a take's grid.

    Attributes
    ----------
    camera : GridCamera
    cam : (H, W, 3) float64
        The grid's points in the camera frame, mm (NaN = no data).
    nose_px : (2,) float64
        Nose tip, px (x right, y down; (0, 0) = centre of the top-left pixel).
    nose_cam : (3,) float64
        Nose tip in the camera frame, mm.
    px_per_mm : float
        Image scale at the nose tip.
    yaw_deg, pitch_deg : float
        Turn of the face plane's normal from the view ray about the vertical and horizontal
        image axes, degrees.
    peak_mm : float
        The nose tip's height above its surroundings, mm.
    """

    camera: GridCamera
    cam: np.ndarray
    nose_px: np.ndarray
    nose_cam: np.ndarray
    px_per_mm: float
    yaw_deg: float
    pitch_deg: float
    peak_mm: float


def _smooth_depth(z: np.ndarray, sigma_px: float) -> np.ndarray:
    """Median (5 x 5: spikes out) then normalised Gaussian smoothing of a depth map with NaN
    holes (NaN stays NaN)."""
    ok = np.isfinite(z)
    far = np.float32(1e6)
    med = cv2.medianBlur(np.where(ok, z, far).astype(np.float32), 5)
    ok &= med < far
    zf = np.where(ok, med, 0.0).astype(np.float32)
    w = ok.astype(np.float32)
    num = cv2.GaussianBlur(zf, (0, 0), sigma_px)
    den = cv2.GaussianBlur(w, (0, 0), sigma_px)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    return np.where(ok & (den > 0.3), out, np.nan).astype(np.float64)


def _probe(far: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``far`` shifted so that each pixel sees the value ``(dx, dy)`` px away (inf outside)."""
    h, w = far.shape
    shifted = np.full(far.shape, np.inf)
    ys, yd = slice(max(dy, 0), h + min(dy, 0)), slice(max(-dy, 0), h + min(-dy, 0))
    xs, xd = slice(max(dx, 0), w + min(dx, 0)), slice(max(-dx, 0), w + min(-dx, 0))
    shifted[yd, xd] = far[ys, xs]
    return shifted


def peak_height(z: np.ndarray, step_px: float) -> np.ndarray:
    """Height of every pixel above the surface around it, mm: a nose tip's.

    The depth ``step_px`` away in eight directions, and half as far to the left and right (a
    nose is narrow, lips and chins are broad), minus the pixel's: the smallest difference.

    Parameters
    ----------
    z : (H, W) float
        Depth, mm (larger = farther), NaN = no data (a probe there is left out).
    step_px : float
        Probe distance, px.

    Returns
    -------
    (H, W) float64
        NaN where ``z`` is, or where fewer than :data:`MIN_PROBES` of the eight probes meet
        data.
    """
    far = np.where(np.isfinite(z), z, np.inf)
    out = np.full(z.shape, np.inf)
    seen = np.zeros(z.shape, dtype=np.int64)
    probes = [(step_px * np.cos(a), step_px * np.sin(a)) for a in np.arange(8) * np.pi / 4]
    for k, (dx, dy) in enumerate(probes + [(step_px / 2, 0.0), (-step_px / 2, 0.0)]):
        shifted = _probe(far, int(round(dx)), int(round(dy)))
        if k < 8:
            seen += np.isfinite(shifted)
        with np.errstate(invalid="ignore"):
            out = np.minimum(out, shifted - far)
    # a peak stands on a surface: most probes must meet data (no isolated specks)
    return np.where(np.isfinite(z) & (seen >= MIN_PROBES), out, np.nan)


def _head_depth(cam: np.ndarray) -> float:
    """Typical depth of the nearest object (a wall behind it is left out), mm."""
    z = cam[::4, ::4, 2]
    near = float(np.nanpercentile(z, 1))
    return float(np.nanmedian(np.where(z < near + HEAD_DEPTH_MM, z, np.nan)))


def _peaks(cam: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Height map (H, W) mm and the smoothed depth (H, W) mm of a grid of ``scale`` px per
    mm."""
    z = cam[..., 2]
    zs = _smooth_depth(z, max(1.0, 2.0 * scale))
    height = peak_height(zs, PEAK_MM * scale)
    # isolated blobs (spikes, hair) are no nose: most of the surroundings must have data
    size = max(3, int(round(2 * PEAK_MM * scale)) | 1)
    share = cv2.blur(np.isfinite(z).astype(np.float32), (size, size))
    return np.where(share > 0.5, height, np.nan), zs


def silhouette_bump(valid: np.ndarray, scale: float) -> float:
    """How far the outline of the data sticks out sideways like a nose in profile, mm.

    Per row the leftmost and rightmost pixels with data; a row's bump is how far its edge
    lies beyond both edges ``PEAK_MM`` above and below it.

    Parameters
    ----------
    valid : (H, W) bool
    scale : float
        px per mm.

    Returns
    -------
    float
        The largest bump over both sides, mm (0 when there are too few rows).
    """
    rows = np.flatnonzero(valid.any(axis=1))
    d = int(round(PEAK_MM * scale))
    if len(rows) < 2 * d + 1 or d < 1:
        return 0.0
    w = valid.shape[1]
    right = np.full(valid.shape[0], np.nan)
    left = np.full(valid.shape[0], np.nan)
    right[rows] = w - 1 - np.argmax(valid[rows, ::-1], axis=1)
    left[rows] = np.argmax(valid[rows], axis=1)
    best = 0.0
    for edge in (right, -left):
        bump = edge[d:-d] - np.fmax(edge[: -2 * d], edge[2 * d :])
        if np.isfinite(bump).any():
            best = max(best, float(np.nanmax(bump)) / scale)
    return best


def _plane_normal(cam: np.ndarray, tip: np.ndarray) -> np.ndarray | None:
    """Unit normal (towards the camera) of the plane fitted to the surface around the nose
    tip, or None when too little surface is there."""
    pts = cam.reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    d = np.linalg.norm(pts - tip, axis=1)
    ring = pts[(d > PLANE_MM[0]) & (d < PLANE_MM[1])]
    if len(ring) < 20:
        return None
    normal = np.linalg.svd(ring - ring.mean(axis=0), full_matrices=False)[2][2]
    return -normal if normal[2] > 0 else normal


def _tip_near(cam: np.ndarray, zs: np.ndarray, tip: np.ndarray) -> tuple[int, int]:
    """Pixel (row, column) of the point within TIP_MM of ``tip`` nearest the camera on the
    smoothed depth ``zs``."""
    d = np.linalg.norm(np.nan_to_num(cam - tip, nan=np.inf), axis=2)
    out = np.where(d < TIP_MM, np.nan_to_num(-zs, nan=-np.inf), -np.inf)
    iy, ix = np.unravel_index(int(np.argmax(out)), out.shape)
    return int(iy), int(ix)


#: Units a take's coordinates may be in instead of mm, tried when no face is found in mm:
#: (name, mm per unit, the sheet's ``units`` value for it).
OTHER_UNITS = (
    ("metres", 1000.0, "m"),
    ("cm", 10.0, "cm"),
    ("inches", 25.4, "25.4"),
    ("0.1 mm", 0.1, "0.1"),
)
#: Refusals that a wrong unit gives (a face 1000 times too small has no nose-like peak; 10
#: times too large, its outline's nose-sized bumps read as a profile, or it reads as a face
#: seen from 10 times farther).
_UNIT_SYMPTOMS = ("no face found", "profile view: no nose", "face too small")


def find_face(xyz: np.ndarray, source: str) -> Face:
    """Find the one face of a take's range grid (:func:`_find_face`); when none is found in mm
    but one is with the coordinates in another unit (:data:`OTHER_UNITS`), the refusal names
    that unit.

    Raises
    ------
    InputError
        As :func:`_find_face`; ``no face found in mm: ...`` naming the unit the take's
        coordinates look like and what to set (the sheet's ``units``, an RGB-D take's
        ``depth_scale_mm``).
    """
    try:
        return _find_face(xyz, source)
    except InputError as exc:
        if not exc.problem.startswith(_UNIT_SYMPTOMS):
            raise
        xyz = np.asarray(xyz, dtype=np.float64)  # (H, W, 3): else refused for its shape
        scale = _grid(xyz)[3]
        for unit, mm, value in OTHER_UNITS:
            if not _searchable(scale / mm, xyz.shape[:2]):
                continue
            try:  # only on the refusal's path: a face at another scale is the evidence
                _find_face(xyz * mm, source)
            except InputError:
                continue
            raise InputError(
                source,
                f"no face found in mm: the surface is a face in {unit} ({mm:g} mm per unit); "
                f"give the take's unit in the sheet's units column ({value}), or an RGB-D "
                f"take's depth_scale_mm x {mm:g} in its intrinsics",
            ) from None
        raise


def _grid(xyz: np.ndarray) -> tuple[int, GridCamera | None, np.ndarray | None, float]:
    """A range grid (H, W, 3), its coordinates read as mm: its number of points with data, its
    camera, its points in the camera frame (H, W, 3) mm and its px per mm at the nearest
    object's depth (no camera, no points and 0 with fewer than :data:`MIN_PIXELS` points)."""
    n_valid = int(np.isfinite(xyz).all(axis=2).sum())
    camera = grid_camera(xyz) if n_valid >= MIN_PIXELS else None
    if camera is None:
        return n_valid, None, None, 0.0
    cam = camera.to_camera(xyz)
    return n_valid, camera, cam, camera.px_per_mm(_head_depth(cam))


def _searchable(scale: float, shape: tuple[int, ...]) -> bool:
    """Whether a face at ``scale`` px per mm could be found in a grid of ``shape`` (H, W): not
    too small, and its nose's probes (``PEAK_MM`` to each side) within the grid."""
    return MIN_PX_PER_MM <= scale and 4 * PEAK_MM * scale < min(shape)


def _find_face(xyz: np.ndarray, source: str) -> Face:
    """Find the one face of a take's range grid, its coordinates in mm.

    Parameters
    ----------
    xyz : (H, W, 3) float
        The take's points, mm, NaN where there is no surface.
    source : str
        Named in errors (``subject/take`` or a file).

    Returns
    -------
    Face

    Raises
    ------
    InputError
        No face found (too little data, no nose-like peak), no face relief (a flat surface:
        :func:`~scan2morph.io.take.flat_surface`), more than one face, a face too small, a profile view
        (yaw beyond :data:`MAX_YAW_DEG`).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[2] != 3:
        raise InputError(source, f"xyz: expected an (H, W, 3) range grid, got shape {xyz.shape}")
    n_valid, camera, cam, scale = _grid(xyz)
    if camera is None:
        raise InputError(source, _too_few_pixels(xyz, n_valid))
    # the search runs on every other pixel of a fine grid (about 1 mm per pixel at 640 x 480)
    stride = 2 if scale >= 1.2 else 1
    coarse = cam[::stride, ::stride]
    height, zs = _peaks(coarse, scale / stride)
    if not np.isfinite(height).any() or np.nanmax(height) < MIN_PEAK_MM:
        best = float(np.nanmax(height)) if np.isfinite(height).any() else 0.0
        if flat := flat_surface(coarse):  # a flat outline's corner is no nose in profile
            raise InputError(
                source,
                f"{flat} and has no nose-like peak (highest {best:.1f} mm, at least "
                f"{MIN_PEAK_MM:g} mm above its surroundings): is this take a scan of a face?",
            )
        nearest = camera.px_per_mm(float(np.nanmin(cam[..., 2])))
        if nearest < MIN_PX_PER_MM:  # no face on the nearest surface would be large enough
            raise InputError(source, _too_small(nearest))
        bump = silhouette_bump(np.isfinite(coarse).all(axis=2), scale / stride)
        if bump >= MIN_PEAK_MM:
            raise InputError(
                source,
                f"profile view: no nose seen from the front (highest peak {best:.1f} mm), but the "
                f"outline sticks out {bump:.0f} mm sideways like a nose in profile; the face "
                f"must be turned at most {MAX_YAW_DEG:g} degrees from the camera",
            )
        raise InputError(
            source,
            f"no face found: no nose-like peak on the surface (highest {best:.1f} mm, at least "
            f"{MIN_PEAK_MM:g} mm above its surroundings)",
        )
    flat = np.nan_to_num(height, nan=-np.inf)
    iy, ix = np.unravel_index(int(np.argmax(flat)), flat.shape)
    tip, peak = coarse[iy, ix], float(flat[iy, ix])
    _refuse_second_face(coarse, flat, tip, peak, stride, source)
    scale = camera.px_per_mm(float(tip[2]))
    if scale < MIN_PX_PER_MM:
        raise InputError(source, _too_small(scale))
    normal = _plane_normal(coarse, tip)
    if normal is None:
        raise InputError(source, "no face found: too little surface around the nose-like peak")
    yaw = float(np.degrees(np.arctan2(normal[0], -normal[2])))
    pitch = float(np.degrees(np.arctan2(normal[1], -normal[2])))
    if abs(yaw) > MAX_YAW_DEG:
        raise InputError(
            source,
            f"profile view: the face is turned about {abs(yaw):.0f} degrees from the camera "
            f"(at most {MAX_YAW_DEG:g} handled)",
        )
    iy, ix = _tip_near(coarse, zs, tip)
    nose_px = stride * np.array([ix, iy], dtype=np.float64)
    return Face(camera, cam, nose_px, coarse[iy, ix], scale, yaw, pitch, peak)


#: Extents of a surface that may be a head, mm: a surface with too few pixels whose two largest
#: extents lie in this range is called a face too small.
HEAD_EXTENT_MM = (60.0, 600.0)


def _too_few_pixels(xyz: np.ndarray, n_valid: int) -> str:
    """The refusal of a grid with fewer than :data:`MIN_PIXELS` points: a face too small when
    they span a head's size (:data:`HEAD_EXTENT_MM`; their px per mm from their count over the
    area of their two largest extents), else no face."""
    problem = f"no face found: {n_valid} pixels have range data (at least {MIN_PIXELS})"
    if n_valid < 20:
        return problem
    b, a = np.sort(np.ptp(xyz[np.isfinite(xyz).all(axis=2)], axis=0))[1:]
    if not HEAD_EXTENT_MM[0] <= b <= a <= HEAD_EXTENT_MM[1]:
        return problem
    detail = f"{n_valid} pixels have range data (at least {MIN_PIXELS}), {a:.0f} x {b:.0f} mm"
    return _too_small(np.sqrt(n_valid / (a * b)), f"{detail}: ")


def _too_small(scale: float, detail: str = "") -> str:
    """The refusal of a face at ``scale`` px per mm (below :data:`MIN_PX_PER_MM`), ``detail``
    after its first words."""
    return (
        f"face too small: {detail}about {90 * scale:.0f} px between the outer eye corners "
        f"(at least {90 * MIN_PX_PER_MM:.0f} px, {MIN_PX_PER_MM:g} px per mm); scan the face from "
        "nearer or at a higher resolution"
    )


def _refuse_second_face(
    cam: np.ndarray, height: np.ndarray, tip: np.ndarray, peak: float, stride: int, source: str
) -> None:
    """Raise when another peak as nose-like as the tip lies far from it (a second face)."""
    dist = np.linalg.norm(np.nan_to_num(cam - tip, nan=np.inf), axis=2)
    other = np.where(dist > OTHER_FACE_MM, height, -np.inf)
    second = float(other.max())
    if second >= max(MIN_PEAK_MM, SECOND_SHARE * peak):
        oy, ox = stride * np.array(np.unravel_index(int(np.argmax(other)), other.shape))
        raise InputError(
            source,
            f"more than one face: a second nose-like peak at pixel ({ox}, {oy}), "
            f"{second:.0f} mm high (the first {peak:.0f} mm); crop the scan to one face",
        )
