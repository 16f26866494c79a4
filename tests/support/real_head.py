"""Where the real head scan of the real-data tests is (never copied into the repository).

"Infinite, 3D Head Scan" by Lee Perry-Smith / Infinite-Realities, CC BY 3.0, read from
``../shared/data/lee-perry-smith`` beside the repository clone (or beside the folder holding a
worktree of it); the tests that read it skip when it is absent.
"""

from __future__ import annotations

from pathlib import Path

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
