"""Sampling the range image at the warped template vertices (Yano-Harada 3.1).

XYZ at a vertex is the bilinear interpolation of the four neighbouring pixels; a vertex with a
neighbour pixel without data (or outside the image) is invalid and gets NaN, never a placeholder.
Texture coordinates come from the pixel position (color and range are pixel to pixel).
"""

from __future__ import annotations

import numpy as np

from scan2morph.errors import InputError
from scan2morph.template.mesh import signed_area2
from scan2morph.template.subdivide import subdivide_template
from scan2morph.template.tps import TPS
from scan2morph.tol import N_IBUG


def sample_range(
    xyz: np.ndarray, points: np.ndarray, source: str = "range image"
) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear samples of a range image.

    Parameters
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
    points : (V, 2) float, pixel coordinates ((0, 0) = centre of the top-left pixel)
    source : str
        Label for error messages.

    Returns
    -------
    vertices : (V, 3) float64, mm; NaN where invalid
    valid : (V,) bool
        True where the point lies in ``[0, W-1] x [0, H-1]`` and all four neighbour pixels have
        data (x, y, z all finite). Non-finite points are invalid.

    Raises
    ------
    InputError
        ``xyz`` not (H, W, 3) with H, W >= 2, or ``points`` not (V, 2).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[2] != 3 or min(xyz.shape[:2]) < 2:
        raise InputError(source, f"xyz: expected (H, W, 3) with H, W >= 2, got {xyz.shape}")
    if points.ndim != 2 or points.shape[1] != 2:
        raise InputError(source, f"points: expected (V, 2) pixel coordinates, got {points.shape}")
    h, w = xyz.shape[:2]
    x, y = points[:, 0], points[:, 1]
    inside = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (y >= 0) & (x <= w - 1) & (y <= h - 1)
    # The last row / column samples the cell to its left / above with weight 1 on its own pixel.
    x0 = np.clip(np.floor(np.where(inside, x, 0)).astype(np.int64), 0, w - 2)
    y0 = np.clip(np.floor(np.where(inside, y, 0)).astype(np.int64), 0, h - 2)
    fx = np.where(inside, x, 0) - x0
    fy = np.where(inside, y, 0) - y0
    x1, y1 = x0 + 1, y0 + 1
    p00, p10, p01, p11 = xyz[y0, x0], xyz[y0, x1], xyz[y1, x0], xyz[y1, x1]
    out = (
        p00 * ((1 - fx) * (1 - fy))[:, None]
        + p10 * (fx * (1 - fy))[:, None]
        + p01 * ((1 - fx) * fy)[:, None]
        + p11 * (fx * fy)[:, None]
    )
    valid = inside & np.all(np.isfinite(np.stack([p00, p10, p01, p11])), axis=(0, 2))
    out[~valid] = np.nan
    return out, valid


def texture_uv(points: np.ndarray, width: int, height: int) -> np.ndarray:
    """Texture coordinates of pixel positions.

    Parameters
    ----------
    points : (V, 2) float
        Pixel coordinates ((0, 0) = centre of the top-left pixel).
    width, height : int
        Image size W, H in pixels.

    Returns
    -------
    uv : (V, 2) float64
        ``u = (x + 0.5) / W``, ``v = (y + 0.5) / H``: image convention, origin at the top-left
        corner of the image (as glTF); the OBJ writer flips v.
    """
    points = np.asarray(points, dtype=np.float64)
    return np.column_stack([(points[:, 0] + 0.5) / width, (points[:, 1] + 0.5) / height])


def folded_faces(points2d: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: warped triangles whose orientation flipped (or collapsed to zero area).

    Template faces have negative signed area in the image frame (see ``template.mesh``).
    """
    return signed_area2(points2d, faces) >= 0


def check_no_folds(
    points2d: np.ndarray, faces: np.ndarray, source: str, max_fraction: float = 0.0
) -> np.ndarray:
    """Check the warp for folds; returns the folded faces when there are few enough.

    A thin-plate spline is not guaranteed one-to-one: with an open mouth a few small triangles
    between the nose and the lips may flip. Up to ``max_fraction`` of the faces may fold (their
    vertices are then marked invalid by the caller); more than that means the landmarks fold the
    template (wrong order, mirrored, or from another face) and is an error naming the take.
    """
    folded = folded_faces(points2d, faces)
    if folded.mean() > max_fraction:
        raise InputError(
            source,
            f"landmarks fold the template: {int(folded.sum())} of {len(faces)} warped triangles flip "
            f"orientation (at most {100 * max_fraction:.1f}% may; check the landmark order: iBUG-68, "
            "left-right as seen in the image)",
        )
    return folded


def fit_take(
    template,
    landmarks: np.ndarray,
    xyz: np.ndarray,
    image_size: tuple[int, int],
    fiducial_set: str = "closed",
    levels: int = 1,
    source: str = "take",
    min_valid_fraction: float = 0.1,
    max_fold_fraction: float = 0.01,
) -> dict[str, np.ndarray]:
    """Fit the template to one take and sample its range image.

    Parameters
    ----------
    template : Template
        The base template.
    landmarks : (68, 2) float
        iBUG-68 landmarks, pixel coordinates.
    xyz : (H, W, 3) float, mm, NaN = no data
    image_size : (width, height)
    fiducial_set : str
        ``"closed"`` or ``"open"`` (see ``template.mesh.FIDUCIAL_SETS``).
    levels : int
        1-to-4 subdivisions.
    source : str
        ``subject/take`` for messages.
    min_valid_fraction : float
        Fewer valid vertices than this share is an error (no range data over the face).
    max_fold_fraction : float
        Share of warped triangles allowed to fold; their vertices are marked invalid.

    Returns
    -------
    dict
        ``vertices`` (V, 3) mm (NaN invalid), ``uv`` (V, 2), ``valid`` (V,), ``points2d`` (V, 2),
        ``faces`` (F, 3), ``n_folded`` (number of folded triangles, whose vertices are invalid).

    Raises
    ------
    InputError
        Naming ``source``: landmarks not (68, 2) or not finite; ``xyz`` not (H, W, 3) or not
        ``image_size``; an unknown fiducial set; fiducials outside the image, coincident or
        collinear; more than ``max_fold_fraction`` folded triangles; fewer than
        ``min_valid_fraction`` valid vertices.
    """
    landmarks = np.asarray(landmarks, dtype=np.float64)
    if landmarks.shape != (N_IBUG, 2):
        raise InputError(source, f"landmarks: expected ({N_IBUG}, 2), got {landmarks.shape}")
    if not np.isfinite(landmarks).all():
        k = int(np.argmax(~np.isfinite(landmarks).all(axis=1)))
        raise InputError(source, f"landmarks: point {k + 1} (iBUG numbering) is not finite")
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[2] != 3:
        raise InputError(source, f"xyz: expected (H, W, 3), got {xyz.shape}")
    width, height = (int(n) for n in image_size)
    if (height, width) != xyz.shape[:2]:
        raise InputError(
            source,
            f"image_size: {width}x{height} (WxH) but the range image is "
            f"{xyz.shape[1]}x{xyz.shape[0]}; landmarks, color and range must be pixel to pixel",
        )
    numbers, base_idx = template.fiducial_set(fiducial_set, source=source)
    dst = landmarks[numbers - 1]
    out = (dst < -0.5).any(axis=1) | (dst[:, 0] > width - 0.5) | (dst[:, 1] > height - 0.5)
    if out.any():
        k = int(np.argmax(out))
        raise InputError(
            source,
            f"fiducials: image point {k} (iBUG {int(numbers[k])}) at {dst[k].round(1).tolist()} "
            f"is outside the {width}x{height} image ({int(out.sum())} fiducials outside)",
        )
    fine = subdivide_template(template, levels)
    spline = TPS.fit(
        template.vertices[base_idx], landmarks[numbers - 1], source=source, image_size=image_size
    )
    points = spline(fine.vertices)
    folded = check_no_folds(points, fine.faces, source, max_fold_fraction)
    vertices, valid = sample_range(xyz, points, source=source)
    valid[np.unique(fine.faces[folded])] = False
    vertices[~valid] = np.nan
    share = float(valid.mean())
    if share < min_valid_fraction:
        raise InputError(
            source,
            f"only {100 * share:.1f}% of the template's vertices fall on range data (expected at "
            f"least {100 * min_valid_fraction:.0f}%): the face region has no range data or the "
            "landmarks do not belong to this scan",
        )
    return {
        "vertices": vertices,
        "uv": texture_uv(points, width, height),
        "valid": valid,
        "points2d": points,
        "faces": np.asarray(fine.faces, dtype=np.int64),
        "n_folded": int(folded.sum()),
    }
