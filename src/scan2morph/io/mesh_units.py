"""A mesh take's unit: the mesh's size and its landmarks' eye span, in mm once scaled by the
sheet's ``units`` column, and the advice when either is not a face's.

A mesh of a face's size in mm is taken to be right, so landmarks on it whose eye span is a
face's in another unit are the landmark file's fault (:func:`check_landmark_units`). A size
that is right as read but wrong with the sheet's unit means the unit is wrong.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.take import EYE_SPAN_MM, likely_unit

#: The largest extent of a face or head scan (a face-only crop to head and shoulders), mm.
MESH_EXTENT_MM = (60.0, 1000.0)
#: What the sheet's ``units`` column takes, for messages.
UNIT_HELP = "mm, cm, m or mm per unit: 25.4 for inches"


def _given_unit_advice(size: float, band: tuple[float, float], mm_per_unit: float) -> str | None:
    """Where the unit goes for a size outside ``band`` (mm, scaled by the sheet's unit
    ``mm_per_unit``, not 1): the units value is wrong when the size as read fits in mm, or the
    unit it looks like as read; None when none fits."""
    as_read = size / mm_per_unit
    if band[0] <= as_read <= band[1]:
        return (
            f"with the unit given ({mm_per_unit:g} mm per unit) it comes out {size:.4g} mm; "
            f"without it, {as_read:.4g} mm, a face's size: the data are in mm already and the "
            "value in the sheet's units column is wrong (leave it empty for mm)"
        )
    unit = likely_unit(as_read, band)
    if unit:
        return (
            f"as read it looks like {unit}, not {mm_per_unit:g} mm per unit: give its unit in "
            f"the sheet's units column ({UNIT_HELP})"
        )
    return None


def check_mesh_size(mesh, mm_per_unit: float = 1.0, source: str | Path = "mesh") -> None:
    """Refuse a mesh that is not face- or head-sized in mm (:data:`MESH_EXTENT_MM` at its
    largest), naming the unit it looks like.

    Without landmarks nothing else checks the unit before the surface searches, which assume mm
    (a head in cm or inches makes their neighbourhoods hold the whole mesh).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        As read, in its own unit.
    mm_per_unit : float
        The sheet's unit (``units`` column), mm.
    source : str or path-like
        The mesh file, for messages.

    Raises
    ------
    InputError
        Naming the mesh's size in mm and the unit it looks like (or, when the sheet's unit
        makes a mesh in mm the wrong size, that the units value is wrong).
    """
    check_mesh_extents(np.asarray(mesh.extents, dtype=np.float64), mm_per_unit, source)


def check_mesh_extents(extents: np.ndarray, mm_per_unit: float, source: str | Path) -> None:
    """:func:`check_mesh_size` on a mesh's extents as read (its own unit)."""
    extents = np.asarray(extents, dtype=np.float64) * mm_per_unit
    largest = float(extents.max())
    lo, hi = MESH_EXTENT_MM
    if lo <= largest <= hi:
        return
    likely = mm_per_unit != 1.0 and _given_unit_advice(largest, MESH_EXTENT_MM, mm_per_unit)
    if not likely and (unit := likely_unit(largest, MESH_EXTENT_MM)):
        likely = f"it looks like {unit}: give its unit in the sheet's units column ({UNIT_HELP})"
    if not likely:
        likely = (
            f"not a face or head in mm: give its scale in the sheet's units column ({UNIT_HELP})"
        )
    size = " x ".join(f"{e:.4g}" for e in extents)
    read = "as read" if mm_per_unit == 1.0 else "in the sheet's unit"
    raise InputError(
        source,
        f"mesh size: {size} mm across {read}, expected a face or head {lo:g}-{hi:g} mm across at its "
        f"largest ({likely})",
    )


def check_landmark_units(
    lm3: np.ndarray, extents_mm: np.ndarray, mesh_path, landmarks_path, mm_per_unit: float = 1.0
) -> None:
    """Refuse 3D landmarks whose outer eye corners (iBUG 37, 46) are not 50-150 mm apart.

    Parameters
    ----------
    lm3 : (68, 3) float
        The landmarks, scaled to mm.
    extents_mm : (3,) float
        The mesh's bounding box, scaled to mm: when it is of a face's size
        (:data:`MESH_EXTENT_MM`) and the eye span is a face's in another unit, the landmark file
        is named (not in the mesh's unit), else the mesh (its unit, or the sheet's, is wrong).
    mesh_path, landmarks_path : str or path-like
        The files, for messages.
    mm_per_unit : float
        The sheet's unit, mm.

    Raises
    ------
    InputError
        Naming the landmark file or the mesh, the eye span and the unit it looks like.
    """
    span = float(np.linalg.norm(lm3[45] - lm3[36]))
    lo, hi = EYE_SPAN_MM
    if lo <= span <= hi:
        return
    unit_read = "units" if mm_per_unit == 1.0 else "mm"
    apart = (
        f"the outer eye corners (iBUG 37, 46) are {span:.4g} {unit_read} apart, expected "
        f"{lo:g}-{hi:g} mm"
    )
    across = float(np.max(extents_mm))
    unit = likely_unit(span, EYE_SPAN_MM)
    if unit and MESH_EXTENT_MM[0] <= across <= MESH_EXTENT_MM[1]:
        looks = f"look like {unit}" if mm_per_unit == 1.0 else "are not in its unit"
        raise InputError(
            landmarks_path,
            f"face size: {apart}, on the mesh {Path(mesh_path).name}, which is {across:.4g} mm "
            f"across (the landmarks {looks}: give them in the mesh's frame and unit)",
        )
    likely = mm_per_unit != 1.0 and _given_unit_advice(span, EYE_SPAN_MM, mm_per_unit)
    if not likely and unit:
        likely = (
            f"the mesh looks like {unit}, not mm: give its unit in the sheet's units column "
            f"({UNIT_HELP})"
        )
    raise InputError(mesh_path, f"face size: {apart} ({likely or 'not a face in mm'})")


__all__ = [
    "MESH_EXTENT_MM",
    "UNIT_HELP",
    "check_landmark_units",
    "check_mesh_extents",
    "check_mesh_size",
]
