"""The ``/template`` group of a subject store."""

from __future__ import annotations

import numpy as np


def template_datasets(template) -> dict[str, np.ndarray]:
    """Store datasets of a (subdivided) template: faces, canonical 2D vertices, fiducials.

    Fiducials are every iBUG point that is a template vertex (named ``ibugNN``, 1-based as in
    iBUG) followed by the named template points (``eye_r_outer``, ``forehead_centre``, ...).
    """
    numbers = np.flatnonzero(template.ibug_vertex >= 0) + 1
    names = [f"ibug{n:02d}" for n in numbers] + list(template.named)
    indices = np.concatenate([template.ibug_vertex[numbers - 1], list(template.named.values())])
    return {
        "/template/faces": np.asarray(template.faces, dtype=np.int64),
        "/template/vertices2d": np.asarray(template.vertices, dtype=np.float64),
        "/template/fiducials/names": np.asarray(names, dtype=object),
        "/template/fiducials/indices": indices.astype(np.int64),
    }
