"""The template fit of a take (Yano-Harada 3.1): the thin-plate spline through its fiducials
(with its forehead rim placed from the neutral's, :mod:`scan2morph.template.rim`), the template
subdivided, warped and sampled from the take's range image (:mod:`scan2morph.template.sample`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError
from scan2morph.template.regions import mouth_faces
from scan2morph.template.rim import Rim, anchored_fiducials, still_affine
from scan2morph.template.sample import check_no_folds, fold_excess, sample_mesh, texture_uv
from scan2morph.template.subdivide import subdivide_template
from scan2morph.template.tps import TPS
from scan2morph.tol import N_IBUG


@dataclass(frozen=True)
class FitRules:
    """How a take's fit is made and sampled: what every fit of a subject shares besides the
    take's own data and fiducial set (:func:`fit_take`).

    Attributes
    ----------
    levels : int
        1-to-4 subdivisions of the template.
    min_valid_fraction : float
        Fewer valid vertices than this share is an error (no range data over the face).
    max_fold_fraction : float
        Share of the warped triangles outside the lips allowed to fold (the lips' may all
        fold); the folded triangles' vertices are marked invalid.
    min_weight : float
        Sampling at the edge of the data (see :func:`~scan2morph.template.sample.sample_range`).
    max_slope_deg : float or None
        Sampling across depth steps, degrees (see
        :func:`~scan2morph.template.sample.sample_range`); also invalidates vertices behind a
        depth step of the fitted mesh (:func:`~scan2morph.template.sample.behind_steps`), both
        along the scanner's viewing direction estimated from the range image
        (:func:`~scan2morph.scan.view.scanner_view`: the XYZ may come in any right-handed
        frame). None: off.
    """

    levels: int = 1
    min_valid_fraction: float = 0.1
    max_fold_fraction: float = 0.01
    min_weight: float = 1.0
    max_slope_deg: float | None = None


def fit_map(
    template,
    landmarks: np.ndarray,
    fiducial_set: str = "closed",
    source: str = "take",
    image_size: tuple[int, int] | None = None,
    rim: Rim | None = None,
) -> TPS:
    """The fit's map from template coordinates to a take's pixels: the thin-plate spline
    through the take's fiducials (:func:`fit_take` samples it at the template's vertices) and,
    with ``rim``, its forehead rim's points placed from the neutral's
    (:mod:`scan2morph.template.rim`).

    Parameters
    ----------
    template : Template
        The base template.
    landmarks : (68, 2) float
        iBUG-68 landmarks, px.
    fiducial_set : str
        As in :func:`fit_take`.
    source : str
        ``subject/take`` for messages.
    image_size : (width, height), optional
        The image, for the spline's checks.
    rim : Rim, optional
        How the rim follows the neutral's (None: the plain spline, as for the neutral itself).

    Returns
    -------
    TPS
        Callable: template coordinates (n, 2) -> pixel coordinates (n, 2).
    """
    numbers, base_idx = template.fiducial_set(fiducial_set, source=source)
    landmarks = np.asarray(landmarks, dtype=np.float64)
    src, dst = template.vertices[base_idx], landmarks[numbers - 1]
    spline = TPS.fit(src, dst, source=source, image_size=image_size)
    if rim is None:
        return spline
    neutral = fit_map(template, rim.neutral_landmarks, rim.neutral_set, f"{source} (neutral)")
    affine = still_affine(rim.neutral_landmarks, landmarks, source)
    src, dst = anchored_fiducials(template, src, dst, spline, neutral, affine, rim.share)
    return TPS.fit(src, dst, source=source)


def fit_take(
    template,
    landmarks: np.ndarray,
    xyz: np.ndarray,
    image_size: tuple[int, int] | None = None,
    fiducial_set: str = "closed",
    rules: FitRules | None = None,
    source: str = "take",
    rim: Rim | None = None,
) -> dict[str, np.ndarray]:
    """Fit the template to one take and sample its range image.

    Parameters
    ----------
    template : Template
        The base template.
    landmarks : (68, 2) float
        iBUG-68 landmarks, pixel coordinates.
    xyz : (H, W, 3) float, mm, NaN = no data
    image_size : (width, height), optional
        The image the landmarks were clicked on; default the range image's (they are pixel to
        pixel).
    fiducial_set : str
        ``"closed"``, ``"open"`` or ``"open_corners"`` (see ``template.mesh.FIDUCIAL_SETS``).
    rules : FitRules, optional
        Subdivisions, validity and fold limits, sampling rules (default :class:`FitRules`'s).
    source : str
        ``subject/take`` for messages.
    rim : Rim, optional
        A take's forehead rim placed from its neutral's (:func:`fit_map`).

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
        collinear; more than ``rules.max_fold_fraction`` folded triangles outside the lips;
        fewer than ``rules.min_valid_fraction`` valid vertices.
    """
    r = FitRules() if rules is None else rules
    landmarks, xyz, (width, height) = _checked_take(landmarks, xyz, image_size, source)
    fine, points = _warp(
        template, landmarks, fiducial_set, (width, height), image_size, r, source, rim
    )
    folded = check_no_folds(points, fine.faces, source, r.max_fold_fraction, mouth_faces(fine))
    exclude = np.unique(fine.faces[folded])
    vertices, valid = sample_mesh(
        xyz, points, fine.faces, source, r.min_weight, r.max_slope_deg, exclude
    )
    share = float(valid.mean())
    min_valid_fraction = r.min_valid_fraction
    if share < min_valid_fraction:
        raise InputError(
            source,
            f"only {100 * share:.1f}% of the template's vertices fall on range data (expected at "
            f"least {100 * min_valid_fraction:g}%): the face region has no range data or the "
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


def fit_folds(
    template,
    landmarks: np.ndarray,
    image_size: tuple[int, int],
    fiducial_set: str = "closed",
    rules: FitRules | None = None,
    source: str = "take",
    rim: Rim | None = None,
) -> bool:
    """Whether :func:`fit_take` would refuse these landmarks for their warp: it folds more than
    ``rules.max_fold_fraction`` of the triangles outside the lips, or the spline cannot be
    fitted (fiducials outside the image, coincident or collinear). The range image's own checks
    (valid vertices) are not made.

    Parameters
    ----------
    template, landmarks, fiducial_set, rules, source, rim
        As in :func:`fit_take`.
    image_size : (width, height)
        The take's grid, px.

    Returns
    -------
    bool
    """
    r = FitRules() if rules is None else rules
    landmarks = np.asarray(landmarks, dtype=np.float64)
    if landmarks.shape != (N_IBUG, 2) or not np.isfinite(landmarks).all():
        return True
    size = tuple(int(n) for n in image_size)
    try:
        fine, points = _warp(template, landmarks, fiducial_set, size, size, r, source, rim)
    except InputError:
        return True
    return fold_excess(points, fine.faces, r.max_fold_fraction, mouth_faces(fine))[2]


def _warp(template, landmarks, fiducial_set, size, image_size, rules, source, rim) -> tuple:
    """``(fine, points)``: the subdivided template (``rules.levels``) and its vertices warped by
    :func:`fit_map` onto the take's grid of ``size`` (width, height), px; an InputError naming
    ``source`` when a fiducial lies outside that grid (``image_size``: the spline's own check,
    None for none)."""
    numbers, _ = template.fiducial_set(fiducial_set, source=source)
    _check_inside(landmarks[numbers - 1], numbers, size, source)
    fine = subdivide_template(template, rules.levels)
    return fine, fit_map(template, landmarks, fiducial_set, source, image_size, rim)(fine.vertices)


def _checked_take(landmarks, xyz, image_size, source: str) -> tuple:
    """``(landmarks (68, 2), xyz (H, W, 3), (width, height))`` as float64 arrays and ints, or
    an InputError naming ``source``: landmarks not (68, 2) or not finite, ``xyz`` not
    (H, W, 3), ``image_size`` (default the range image's) other than the range image's."""
    landmarks = np.asarray(landmarks, dtype=np.float64)
    if landmarks.shape != (N_IBUG, 2):
        raise InputError(source, f"landmarks: expected ({N_IBUG}, 2), got {landmarks.shape}")
    if not np.isfinite(landmarks).all():
        k = int(np.argmax(~np.isfinite(landmarks).all(axis=1)))
        raise InputError(source, f"landmarks: point {k + 1} (iBUG numbering) is not finite")
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 3 or xyz.shape[2] != 3:
        raise InputError(source, f"xyz: expected (H, W, 3), got {xyz.shape}")
    if image_size is None:
        image_size = (xyz.shape[1], xyz.shape[0])
    width, height = (int(n) for n in image_size)
    if (height, width) != xyz.shape[:2]:
        raise InputError(
            source,
            f"image_size: {width}x{height} (WxH) but the range image is "
            f"{xyz.shape[1]}x{xyz.shape[0]}; landmarks, color and range must be pixel to pixel",
        )
    return landmarks, xyz, (width, height)


def _check_inside(dst: np.ndarray, numbers: np.ndarray, size: tuple, source: str) -> None:
    """An InputError unless every fiducial ``dst`` (n, 2) px (iBUG ``numbers`` (n,)) lies in
    the image of ``size`` ``(width, height)``."""
    width, height = size
    out = (dst < -0.5).any(axis=1) | (dst[:, 0] > width - 0.5) | (dst[:, 1] > height - 0.5)
    if out.any():
        k = int(np.argmax(out))
        raise InputError(
            source,
            f"fiducials: image point {k} (iBUG {int(numbers[k])}) at {dst[k].round(1).tolist()} "
            f"is outside the {width}x{height} image ({int(out.sum())} fiducials outside)",
        )
