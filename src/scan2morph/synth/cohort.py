"""Synthetic takes with exact ground truth, written in the formats users bring.

A subject's identity comes from ``(seed, subject)``; a take's articulation intensity, head pose
and scanner defects from ``(seed, subject, take)``. The same inputs give byte-identical
outputs.
"""

from __future__ import annotations

import hashlib
import re
from os import PathLike

import numpy as np

from scan2morph.errors import InputError
from scan2morph.jobs import write_npz
from scan2morph.synth.convention import landmark_vertices
from scan2morph.synth.head import (
    LABEL_KIND,
    HeadModel,
    Identity,
    articulate,
    build_head,
    label_coefficients,
    sample_identity,
)
from scan2morph.synth.scanner import ScanDefects, camera_matrix, head_pose, project, scan
from scan2morph.synth.texture import texture_seed

#: Scanner and camera parameters of a synthetic take, with their defaults.
DEFAULT_PARAMS: dict[str, float | int] = {
    "width": 640,  # image width, pixels
    "height": 480,  # image height, pixels
    "focal_px": 1450.0,  # focal length, pixels
    "distance_mm": 1000.0,  # camera to the front of the face along the optical axis
    "pose_sigma_deg": 2.0,  # random head rotation, per axis
    "pose_sigma_mm": 10.0,  # random head translation, per axis
    "noise_mm": 0.1,  # depth noise along the ray
    "spike_fraction": 0.001,  # fraction of measured pixels turned into spikes
    "spike_mm": 30.0,  # typical spike displacement
    "hole_blobs": 4,  # random round holes on the skin
    "click_noise_px": 0.5,  # landmark clicking noise
    "grazing_deg": 75.0,  # dropout beyond this angle between normal and view ray
    "skin_texture": 1.0,  # strength of the skin's freckles and mottling (0: flat albedo)
}

_INT_PARAMS = ("width", "height", "hole_blobs")
_ID_RE = re.compile(r"^[A-Za-z0-9_-]+$")
#: Head-frame point put on the optical axis: mid-face height (between the hairline and the
#: chin), at the front of the face.
AIM = np.array([0.0, -14.0, 95.0])


def default_takes() -> list[tuple[str, str, str]]:
    """The default takes of a synthetic subject.

    Returns
    -------
    list of (take, kind, label)
        The neutral, the five visemes (take id = label), two smiles, two sad faces, a strong
        inner-brow raise and a frown (``config/config.yaml``'s ``synthetic.takes``).
    """
    takes = [("neutral", "neutral", "neutral")]
    takes += [(v, "viseme", v) for v in ("car", "man", "she", "eel", "too")]
    takes += [("smile1", "expression", "smile"), ("smile2", "expression", "smile")]
    takes += [("sad1", "expression", "sad"), ("sad2", "expression", "sad")]
    takes += [("brows1", "expression", "brows"), ("frown1", "expression", "frown")]
    return takes


def text_seed(text: str) -> int:
    """A 64-bit seed (int) fixed by ``text`` (its SHA-256): the same in every process, unlike
    ``hash``."""
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "little")


def subject_identity(subject: str, seed: int) -> Identity:
    """The identity of a synthetic subject, fixed by ``(seed, subject)``.

    Parameters
    ----------
    subject : str
    seed : int
        Non-negative cohort seed.

    Returns
    -------
    Identity
    """
    return sample_identity(np.random.default_rng([int(seed), text_seed(subject)]))


def numeric_params(
    params: dict | None,
    defaults: dict[str, float | int],
    int_keys: tuple[str, ...],
    source: str,
) -> dict:
    """``defaults`` updated with ``params``: known keys, finite numbers, integers where needed.

    Parameters
    ----------
    params : dict or None
        Overrides.
    defaults : dict
        Every accepted key with its default.
    int_keys : tuple of str
        Keys whose values must be integers.
    source : str
        Named in the errors (``subject/take``).

    Returns
    -------
    dict
        Every key of ``defaults``; ``int`` for ``int_keys``, ``float`` otherwise.

    Raises
    ------
    InputError
        ``params`` not a dict, an unknown key, a value that is not a finite number, a
        non-integer value for an integer key.
    """
    out = dict(defaults)
    if params is None:
        return out
    if not isinstance(params, dict):
        raise InputError(source, f"params: expected a dict, got {type(params).__name__}")
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        raise InputError(
            source, f"params: unknown key(s) {unknown}; expected some of {sorted(defaults)}"
        )
    for k, v in params.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise InputError(source, f"params.{k}: expected a number, got {v!r}")
        if not np.isfinite(v):
            raise InputError(source, f"params.{k}: expected a finite number, got {v!r}")
        if k in int_keys and float(v) != int(v):
            raise InputError(source, f"params.{k}: expected an integer, got {v!r}")
        out[k] = int(v) if k in int_keys else float(v)
    for k in ("width", "height"):
        if k in out and not 16 <= out[k] <= 4096:
            raise InputError(source, f"params.{k}: expected 16..4096 pixels, got {out[k]}")
    return out


def _check_params(params: dict | None, source: str) -> dict:
    out = numeric_params(params, DEFAULT_PARAMS, _INT_PARAMS, source)
    for k in ("focal_px", "distance_mm"):
        if out[k] <= 0:
            raise InputError(source, f"params.{k}: expected > 0, got {out[k]}")
    if out["distance_mm"] < 300.0:
        raise InputError(
            source, f"params.distance_mm: expected >= 300 mm, got {out['distance_mm']}"
        )
    for k in (
        "pose_sigma_deg",
        "pose_sigma_mm",
        "noise_mm",
        "spike_mm",
        "hole_blobs",
        "click_noise_px",
        "skin_texture",
    ):
        if out[k] < 0:
            raise InputError(source, f"params.{k}: expected >= 0, got {out[k]}")
    if not 0.0 <= out["spike_fraction"] <= 0.5:
        raise InputError(
            source, f"params.spike_fraction: expected 0..0.5, got {out['spike_fraction']}"
        )
    if not 0.0 < out["grazing_deg"] <= 90.0:
        raise InputError(
            source, f"params.grazing_deg: expected in (0, 90], got {out['grazing_deg']}"
        )
    return out


def check_take(subject: str, label: str, kind: str, take: str, seed: int) -> str:
    """Check the ids, label, kind and seed of a simulated take.

    Returns
    -------
    str
        ``subject/take``, the source named in errors.

    Raises
    ------
    InputError
        On an unknown label, a kind that does not match it, a bad id or seed.
    """
    source = f"{subject}/{take}"
    for name, value in (("subject", subject), ("take", take)):
        if not isinstance(value, str) or not _ID_RE.match(value):
            raise InputError(source, f"{name}: expected letters, digits, '_' or '-', got {value!r}")
    if label not in LABEL_KIND:
        raise InputError(source, f"label: expected one of {sorted(LABEL_KIND)}, got {label!r}")
    if kind != LABEL_KIND[label]:
        raise InputError(
            source, f"kind: label {label!r} is a {LABEL_KIND[label]!r} take, got {kind!r}"
        )
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(source, f"seed: expected a non-negative integer, got {seed!r}")
    return source


def articulated_head(
    subject: str, label: str, kind: str, take: str, seed: int, identity: Identity | None = None
) -> tuple[HeadModel, np.ndarray, np.random.Generator]:
    """The checked set-up shared by every simulated take: head, deformed vertices, take rng.

    Parameters
    ----------
    subject, label, kind, take, seed
        As in :func:`make_take`.
    identity : Identity, optional
        The face instead of the subject's own (:func:`subject_identity`): the detector's
        trainer draws wider faces than a cohort's. The take's randomness stays the subject's.

    Returns
    -------
    head : HeadModel
        The subject's head (cached per identity).
    vertices : (N, 3) float64
        The head articulated for ``label`` at this take's intensity, head frame, mm.
    rng : numpy.random.Generator
        The take's generator, fixed by ``(seed, subject, take)``, after drawing the intensity;
        the caller draws the pose and the defects from it.

    Raises
    ------
    InputError
        On an unknown label, a kind that does not match it, a bad id or seed.
    """
    check_take(subject, label, kind, take, seed)
    head = build_head(subject_identity(subject, seed) if identity is None else identity)
    rng = np.random.default_rng([int(seed), text_seed(subject), text_seed(take)])
    coeffs = label_coefficients(label, rng if label != "neutral" else None)
    return head, articulate(head, coeffs), rng


def make_take(
    subject: str,
    label: str,
    kind: str,
    take: str,
    seed: int,
    params: dict | None = None,
    convention: str = "synth",
) -> dict:
    """Simulate one scan of a synthetic subject.

    Parameters
    ----------
    subject : str
        Subject id (letters, digits, ``_``, ``-``); with ``seed`` it fixes the identity.
    label : str
        ``neutral``, a viseme (``car``, ``man``, ``she``, ``eel``, ``too``) or an expression
        (``smile``, ``sad``).
    kind : str
        ``neutral``, ``viseme`` or ``expression``; must match the label.
    take : str
        Take id; with ``seed`` and ``subject`` it fixes the intensity, pose and defects.
    seed : int
        Non-negative cohort seed.
    params : dict, optional
        Overrides of :data:`DEFAULT_PARAMS`.
    convention : str
        Landmark conventions of the truth (``landmarks``, ``landmarks3d``, ``landmarks2d``): one
        of :data:`~scan2morph.synth.convention.CONVENTIONS`, the generator's own by default.

    Returns
    -------
    dict
        ``xyz`` (H, W, 3) float64 mm in the scanner frame, NaN = no data; ``color`` (H, W, 3)
        uint8; ``landmarks`` (68, 2) float64 pixel coordinates with click noise; ``truth``
        (dict of arrays, see :func:`write_take`); ``subject``, ``take``, ``kind``, ``label``.

    Raises
    ------
    InputError
        On an unknown label, a kind that does not match it, a bad id or seed, or bad params.
    """
    p = _check_params(params, check_take(subject, label, kind, take, seed))
    head, vertices, rng = articulated_head(subject, label, kind, take, seed)
    K = camera_matrix(p["width"], p["height"], p["focal_px"])
    pose = head_pose(rng, p["distance_mm"], p["pose_sigma_deg"], p["pose_sigma_mm"], AIM)
    defects = ScanDefects(
        p["noise_mm"],
        p["spike_fraction"],
        p["spike_mm"],
        p["hole_blobs"],
        p["grazing_deg"],
        p["skin_texture"],
        texture_seed(subject, seed),
    )
    out = scan(head, vertices, pose, K, p["width"], p["height"], rng, defects)
    lm_index = landmark_vertices(head, vertices, pose, convention)
    lm3 = vertices[lm_index] @ pose[:3, :3].T + pose[:3, 3]
    lm2 = project(K, lm3)
    clicked = lm2 + p["click_noise_px"] * rng.standard_normal(lm2.shape)
    truth = _take_truth(head, vertices, pose, {"K": K}, lm3, lm2)
    images = {"xyz": out["xyz"], "color": out["color"]}
    return _take_result(images, clicked, truth, subject, take, kind, label)


def _take_truth(
    head: HeadModel,
    vertices: np.ndarray,
    pose: np.ndarray,
    camera: dict[str, np.ndarray],
    lm3: np.ndarray,
    lm2: np.ndarray,
    **extra: np.ndarray,
) -> dict[str, np.ndarray]:
    """The truth arrays of a take, in the order they are written (see :func:`write_take`).

    Parameters
    ----------
    head : HeadModel
    vertices : (N, 3) float64
        The articulated head, head frame, mm.
    pose : (4, 4) float64
        Head -> camera.
    camera : dict of str to array
        The camera's intrinsics (``K``, and ``D`` for a distorted camera), stored after ``pose``.
    lm3 : (68, 3) float64
        Landmarks in the camera frame, mm.
    lm2 : (68, 2) float64
        Their exact projections, px.
    **extra : array
        Further arrays, stored last, in the given order.
    """
    return {
        "vertices": vertices,
        "faces": np.array(head.faces, dtype=np.int64),
        "skin_faces": head.skin_faces,
        "pose": pose,
        **camera,
        "landmarks3d": lm3,
        "landmarks2d": lm2,
        "displacement": vertices - head.vertices,
        **extra,
    }


def _take_result(
    images: dict, clicked: np.ndarray, truth: dict, subject: str, take: str, kind: str, label: str
) -> dict:
    """A simulated take as returned to the caller: the images, then landmarks, truth and ids."""
    return {
        **images,
        "landmarks": clicked,
        "truth": truth,
        "subject": subject,
        "take": take,
        "kind": kind,
        "label": label,
    }


def _check_result(result: dict, keys: tuple[str, ...], source: str, producer: str) -> None:
    """Raise :class:`InputError` naming ``source`` unless ``result`` has every key of ``keys``."""
    for key in keys:
        if key not in result:
            raise InputError(source, f"result: missing key {key!r} (expected {producer} output)")


def write_take(
    result: dict,
    xyz_path: str | PathLike[str],
    color_path: str | PathLike[str],
    pts_path: str | PathLike[str],
    truth_path: str | PathLike[str],
) -> None:
    """Write a take from :func:`make_take` as a user would bring it, plus its truth.

    Parameters
    ----------
    result : dict
        Output of :func:`make_take`.
    xyz_path : str or path-like
        FRGC ``.abs`` / ``.abs.gz`` range image (NaN -> flag 0).
    color_path : str or path-like
        Colour image (PNG).
    pts_path : str or path-like
        iBUG 68-point ``.pts`` (1-based).
    truth_path : str or path-like
        ``.npz`` with ``vertices`` (N, 3) head frame mm, ``faces`` (F, 3), ``skin_faces``
        (F,) bool, ``pose`` (4, 4) head -> scanner, ``K`` (3, 3), ``landmarks3d`` (68, 3)
        scanner frame, ``landmarks2d`` (68, 2) exact projections, ``displacement`` (N, 3)
        this take minus the neutral, head frame.
    """
    from scan2morph.io import write_abs, write_color, write_pts

    _check_result(result, ("xyz", "color", "landmarks", "truth"), str(truth_path), "make_take")
    write_abs(xyz_path, result["xyz"])
    write_color(color_path, result["color"])
    write_pts(pts_path, result["landmarks"])
    write_npz(truth_path, result["truth"])
