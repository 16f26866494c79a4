"""The sheet's ``units`` column: a take's coordinate unit, in mm per unit.

A base module (no pandas, no numpy): the sheet check, the subject check and the ingest read it.
"""

from __future__ import annotations

import math

#: The ``units`` column's names: the unit of a take's coordinates -> mm per unit (empty: mm).
UNITS = {"": 1.0, "mm": 1.0, "cm": 10.0, "m": 1000.0}
#: Modalities whose coordinates the ``units`` column scales (the others carry their unit in
#: their own files: a stereo calibration's T, an RGB-D sensor's depth_scale_mm).
UNITS_MODALITIES = ("mesh", "range")


def unit_scale(value) -> float | None:
    """mm per unit of a ``units`` cell: ``mm``, ``cm``, ``m`` (:data:`UNITS`; empty: mm) or a
    positive number of mm per unit (a scan in inches: 25.4; a photogrammetry mesh of unknown
    scale: the factor that makes it mm); None when the cell is neither."""
    value = str(value or "").strip()
    if value.lower() in UNITS:  # MM, Cm, M as well
        return UNITS[value.lower()]
    try:
        scale = float(value)
    except ValueError:
        return None
    return scale if math.isfinite(scale) and scale > 0 else None


def units_problem(value: str, modality: str) -> str:
    """What is wrong with a ``units`` cell, naming the column; ``""`` when nothing."""
    value = str(value or "")
    scale = unit_scale(value)
    if scale is None:
        return (
            f"column 'units': {value!r} unknown (expected mm, cm, m or a number of mm per unit, "
            "e.g. 25.4 for inches; empty means mm)"
        )
    if scale != 1.0 and modality not in UNITS_MODALITIES:
        return (
            f"column 'units': {value!r} is for mesh and range takes (a {modality} take gives its "
            "unit in its own files: a stereo calibration's T, an RGB-D sensor's depth_scale_mm)"
        )
    return ""


def units_hint(mm_per_unit: float) -> str:
    """What a range take's face-size error adds about the sheet's ``units`` column: the scale it
    applied, when it applied one (the xyz is then read as that unit), else where to give one.

    Parameters
    ----------
    mm_per_unit : float
        The take's unit as the ingest applies it (:func:`unit_scale`), mm.

    Returns
    -------
    str
        Starting with ``"; "``, to append to the error.
    """
    if mm_per_unit == 1.0:
        return "; give the xyz's unit in the sheet's units column if it is not mm"
    return (
        f"; the sheet's units column scaled the xyz by {mm_per_unit:g} mm per unit: is that the "
        "xyz's unit?"
    )


__all__ = ["UNITS", "UNITS_MODALITIES", "unit_scale", "units_hint", "units_problem"]
