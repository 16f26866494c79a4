"""Where the real head scan of the real-data tests is (never copied into the repository).

"Infinite, 3D Head Scan" by Lee Perry-Smith / Infinite-Realities, CC BY 3.0, read from
``../shared/data/lee-perry-smith`` beside the repository clone (or beside the folder holding a
worktree of it); the tests that read it skip when it is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

_REPO = Path(__file__).resolve().parents[2]
#: The scan's folder (the first ``shared/data`` found beside the clone or its worktree folder).
DATA_DIR = next(
    (
        p / "shared" / "data" / "lee-perry-smith"
        for p in _REPO.parents[:2]
        if (p / "shared" / "data").is_dir()
    ),
    _REPO.parent / "shared" / "data" / "lee-perry-smith",
)
#: The mesh (glTF binary, arbitrary units, face toward +z, +y up; its UVs run OBJ-style).
GLB = DATA_DIR / "LeePerrySmith.glb"
#: Its colour map (1024 x 1024 JPEG).
COLOR_MAP = DATA_DIR / "Map-COL.jpg"


def smile_displacement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smile-like displacement (V, 3) in the model frame, mm, at face coordinates relative to
    the nose tip (x right, y up): the cheeks 5 mm up and out, the lower temples 2 mm, the mouth
    corners 6 mm."""

    def bump(cx, cy, sigma):
        return np.exp(-((np.abs(x) - cx) ** 2 + (y - cy) ** 2) / (2 * sigma * sigma))[:, None]

    return (
        5.0 * bump(38, -10, 12) * [0.0, 0.8, 0.6]
        + 2.0 * bump(58, 20, 10) * [0.0, 0.5, 0.8]
        + 6.0 * bump(25, -40, 10) * [0.0, 0.6, 0.3]
    )
