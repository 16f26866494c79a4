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


def stable_face(template) -> np.ndarray:
    """Vertices that neither visemes nor common expressions move: ICP's default region.

    The upper forehead (more than 0.35 template units, about 16 mm, above the inner brow ends:
    brows rise when sad or surprised), the nose ridge between the bridge and the tip, and the
    temples (outside the outer eye corners, above the cheekbones: cheeks rise in a smile).
    Measured on the synthetic range subjects, ICP on this region alone aligns smiles and sad
    faces to < 0.16 degrees and < 0.15 mm, where the whole face above the nose tip gives up to
    0.6 degrees and 0.9 mm. A smile moves its lower temples by 1-3 mm, though, and once those are
    trimmed the rest constrains the rotation poorly (mesh and RGB-D takes: up to 0.21 and 0.38
    degrees); the align stage therefore grows the region into the upper face's still skin
    (``align.grow_into``, :func:`~scan2morph.align.align_take`'s ``grow_indices``).

    Returns
    -------
    region : (V,) bool
    """
    x, y = template.vertices[:, 0], template.vertices[:, 1]
    named = template.named
    brow = template.vertices[[named["brow_r_inner"], named["brow_l_inner"]], 1].min()
    bridge, tip = (
        template.vertices[named["nose_bridge"], 1],
        template.vertices[named["nose_tip"], 1],
    )
    forehead = y < brow - 0.35
    ridge = (np.abs(x) < 0.22) & (y > bridge) & (y < tip)
    temples = (np.abs(x) > 1.05) & (y < 0.3)
    return forehead | ridge | temples


def icp_region(template, name: str) -> np.ndarray:
    """The ICP region named in config: ``stable`` (:func:`stable_face`) or ``upper_face``."""
    if name == "stable":
        return stable_face(template)
    if name == "upper_face":
        return upper_face(template)
    raise InputError(
        "config", f"align.icp_region: {name!r} unknown (expected 'stable' or 'upper_face')"
    )


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
