"""Viseme models and expression displacement fields of one subject (Yano-Harada 4.1, 5).

Given the template faces, the neutral mesh and every other take's mesh aligned into the neutral
frame, this computes what the store keeps: the stencil mask, raw and processed motion per viseme,
the viseme models (neutral + processed motion) and the expression displacement fields (aligned
take minus neutral, invalid vertices filled from neighbours, smoothed but not masked).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import harmonic_fill
from scan2morph.motion.mask import stencil_mask
from scan2morph.motion.smooth import Relief, laplacian_smooth
from scan2morph.motion.vectors import motion_vectors
from scan2morph.store import paths


@dataclass(frozen=True)
class AlignedMesh:
    """A take's mesh in the neutral frame: ``vertices`` (V, 3) mm (NaN = invalid), ``valid`` (V,)
    and, when the dense refinement measured its correspondence, ``confidence`` (V,) in [0, 1]
    (:mod:`scan2morph.refine`; None: every vertex placed by the template fit alone)."""

    vertices: np.ndarray
    valid: np.ndarray
    confidence: np.ndarray | None = None


def complete_neutral(
    neutral: AlignedMesh, faces: np.ndarray, source: str
) -> tuple[np.ndarray, np.ndarray]:
    """The neutral mesh with invalid vertices filled by harmonic interpolation.

    Returns
    -------
    vertices : (V, 3) float64, mm, all finite
    filled : (V,) bool, the vertices that were filled
    """
    filled = ~neutral.valid | ~np.isfinite(neutral.vertices).all(axis=1)
    vertices = harmonic_fill(neutral.vertices, faces, ~filled)
    if not np.isfinite(vertices).all():
        raise InputError(
            source, "neutral mesh: a part of the template has no valid vertex to fill it from"
        )
    return vertices, filled


def _raw_motion(
    mesh: AlignedMesh, neutral: AlignedMesh, faces: np.ndarray, max_stretch: float, source: str
) -> np.ndarray:
    """A take's raw motion: NaN where either mesh is invalid or the take tore off the face."""
    return motion_vectors(
        mesh.vertices,
        neutral.vertices,
        mesh.valid,
        neutral.valid,
        source=source,
        faces=faces,
        max_stretch=max_stretch,
    )


@dataclass(frozen=True)
class VisemeSmoothing:
    """How :func:`viseme_motion` masks and smooths.

    Attributes
    ----------
    radius_mm : float
        Sphere radius of the stencil mask, mm.
    w : float
        Laplacian smoothing weight.
    iterations : int
        Laplacian smoothing iterations.
    max_stretch : float
        Take vertices torn off the face beyond this stretch count as invalid
        (:func:`~scan2morph.motion.vectors.motion_vectors`).
    relief : float
        Share of the smoothing step taken off where a viseme's correspondence was measured with
        confidence 1 (:func:`~scan2morph.motion.smooth.laplacian_smooth`; 0: the paper's step).
    """

    radius_mm: float
    w: float
    iterations: int
    max_stretch: float = np.inf
    relief: float = 0.0


def viseme_motion(
    neutral: AlignedMesh,
    visemes: dict[str, AlignedMesh],
    faces: np.ndarray,
    mask_paths: np.ndarray,
    smoothing: VisemeSmoothing,
    source: str,
) -> dict[str, np.ndarray]:
    """Mask, motion vectors and viseme models.

    Parameters
    ----------
    neutral : AlignedMesh
    visemes : dict take -> AlignedMesh (aligned into the neutral frame)
    faces : (F, 3) int
    mask_paths : (P, 2) int
        Start and goal vertices of the Dijkstra paths that seed the stencil mask.
    smoothing : VisemeSmoothing
        The mask's radius and the smoothing.
    source : str
        ``subject`` label for messages.

    Returns
    -------
    dict of store path -> array
        ``/mask/suppressed`` (V,), ``/mask/seeds`` (S,), ``/neutral/vertices`` (V, 3),
        ``/neutral/filled`` (V,), and per viseme ``/visemes/{take}/motion_raw``,
        ``/visemes/{take}/motion``, ``/visemes/{take}/model``.
    """
    sm = smoothing
    base, filled = complete_neutral(neutral, faces, source)
    suppressed, seeds = stencil_mask(base, faces, mask_paths, radius_mm=sm.radius_mm, source=source)
    out = {
        paths.mask("suppressed"): suppressed,
        paths.mask("seeds"): seeds,
        paths.neutral("vertices"): base,
        paths.neutral("filled"): filled,
    }
    for take, mesh in visemes.items():
        raw = _raw_motion(mesh, neutral, faces, sm.max_stretch, f"{source}/{take}")
        missing = ~np.isfinite(raw).all(axis=1)
        smooth = laplacian_smooth(
            raw,
            faces,
            w=sm.w,
            iterations=sm.iterations,
            fixed=suppressed,
            missing=missing,
            source=f"{source}/{take}",
            relief=Relief(mesh.confidence, sm.relief),
        )
        out[paths.viseme(take, "motion_raw")] = raw
        out[paths.viseme(take, "motion")] = smooth
        out[paths.viseme(take, "model")] = base + smooth
    return out


def expression_displacements(
    neutral: AlignedMesh,
    expressions: dict[str, AlignedMesh],
    faces: np.ndarray,
    source: str,
    max_stretch: float = np.inf,
    w: float = 0.1,
    iterations: int = 0,
    relief: float = 0.0,
) -> dict[str, np.ndarray]:
    """``/expressions/{take}/displacement`` (V, 3) mm: aligned take minus neutral, invalid (and,
    with a finite ``max_stretch``, torn-off) vertices filled, then smoothed by ``iterations``
    Laplacian steps of ``w`` (shorter by ``relief`` where the refinement measured the skin, see
    :func:`~scan2morph.motion.smooth.laplacian_smooth`; 0 steps: filled only). No mask: the
    modal basis spans the whole face."""
    out = {}
    for take, mesh in expressions.items():
        raw = _raw_motion(mesh, neutral, faces, max_stretch, f"{source}/{take}")
        out[paths.expression(take, "displacement")] = laplacian_smooth(
            raw,
            faces,
            w=w,
            iterations=iterations,
            missing=~np.isfinite(raw).all(axis=1),
            source=f"{source}/{take}",
            relief=Relief(mesh.confidence, relief),
        )
    return out
