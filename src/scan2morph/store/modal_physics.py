"""What a store records of its modal basis's physics (``/modal/physics``), read once for the
figures and the report."""

from __future__ import annotations

import json
from collections.abc import Mapping

from scan2morph.store import paths
from scan2morph.store.warnings import text_value


def modal_physics(store: Mapping) -> dict:
    """``/modal/physics`` (the basis's settings, JSON) as a dict: empty for a store without
    one, or whose value is not a JSON object.

    Parameters
    ----------
    store : mapping store path -> array, or an open h5py file
    """
    key = paths.modal("physics")
    if key not in store:
        return {}
    value = store[key]
    if not hasattr(value, "asstr") and hasattr(value, "item"):  # a 0-d array of read_part's
        value = value.item()
    try:
        out = json.loads(text_value(value))
    except ValueError:
        return {}
    return out if isinstance(out, dict) else {}


def vertex_coordinates(store: Mapping) -> bool:
    """Whether the stored modes are the natural modes orthonormalised per vertex (coordinates
    ``vertex``, the ``skin`` presets): mode j is natural mode j plus a combination of the ones
    before it, its frequency a Rayleigh quotient (not in ascending order), and the coordinates
    q = Q^T W v with W the mass shared equally by the vertices."""
    return modal_physics(store).get("coordinates") == "vertex"


__all__ = ["modal_physics", "vertex_coordinates"]
