"""Vertex regions of the template, defined in its canonical frame (so they hold for every take)."""

from __future__ import annotations

import numpy as np

from scan2morph.errors import InputError


def upper_face(template, above: str = "nose_tip") -> np.ndarray:
    """Vertices above a named template point (the face part a mouth does not move).

    Parameters
    ----------
    template : Template
        Base or subdivided template (canonical frame: y down).
    above : str
        A key of ``template.named``; vertices with a smaller canonical y (higher on the face)
        belong to the region.

    Returns
    -------
    region : (V,) bool
    """
    if above not in template.named:
        raise InputError(
            "template",
            f"region bound {above!r} is not a named vertex (known: {sorted(template.named)})",
        )
    y0 = template.vertices[template.named[above], 1]
    return template.vertices[:, 1] < y0


def named_indices(template, names, what: str) -> np.ndarray:
    """Vertex indices of named template points, with a clear error for an unknown name.

    Parameters
    ----------
    template : Template
    names : sequence of str, or sequence of (str, str) pairs
    what : str
        The config key the names come from, for the message (e.g. ``"align.point_pairs"``).

    Returns
    -------
    indices : int64 array of the same shape as ``names``
    """
    arr = np.asarray(names, dtype=object)
    flat = []
    for name in arr.ravel():
        if name not in template.named:
            raise InputError(
                "config",
                f"{what}: {name!r} is not a named template vertex (known: {sorted(template.named)})",
            )
        flat.append(template.named[name])
    return np.asarray(flat, dtype=np.int64).reshape(arr.shape)
