"""A take's clicked landmarks with the data they sit on: what refits and click statistics need."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from scan2morph.store import paths


@dataclass(frozen=True)
class ClickedTake:
    """One take as the fit sees it.

    Attributes
    ----------
    xyz : (H, W, 3) float, mm, NaN = no data
        The repaired range image.
    landmarks : (68, 2) float, px
        The clicked iBUG-68 landmarks.
    fiducial_set : str
        The take's fiducial set (``template.fiducials`` of its kind).
    transform : (4, 4) float
        The take's alignment to the neutral (identity for the neutral).
    motion : (V, 3) float, mm, optional
        The take's final motion as the pipeline made it from these clicks
        (``/visemes/{take}/motion``), when known: the click-noise draws' reference, which is
        otherwise refitted from the clicks (the same numbers).
    """

    xyz: np.ndarray
    landmarks: np.ndarray
    fiducial_set: str
    transform: np.ndarray
    motion: np.ndarray | None = None


def clicked_take(store: Mapping[str, np.ndarray], take: str, fiducial_set: str) -> ClickedTake:
    """A take's repaired range image, clicks and alignment from (a merge of) its store parts.

    Reads ``/takes/{take}/range/xyz``, ``/takes/{take}/landmarks`` and, when present,
    ``/takes/{take}/align/transform`` (identity otherwise: the neutral) and
    ``/visemes/{take}/motion``.
    """
    transform = store.get(paths.align(take, "transform"))
    return ClickedTake(
        store[paths.range_image(take, "xyz")],
        store[paths.landmarks(take)],
        fiducial_set,
        np.eye(4) if transform is None else transform,
        store.get(paths.viseme(take, "motion")),
    )
