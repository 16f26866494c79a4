"""Ground truth of a synthetic take (the ``truth/{take}.npz`` the generator writes).

Keys: ``vertices`` (N, 3) head frame mm, ``faces`` (F, 3), ``skin_faces`` (F,) bool, ``pose`` (4, 4)
head -> scanner frame, ``K`` (3, 3), ``landmarks3d`` (68, 3) scanner frame, ``landmarks2d`` (68, 2),
``displacement`` (N, 3) head frame (take minus neutral). Stereo takes may add ``xyz_true``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.open3d_light import open3d, triangle_scene

_KEYS = (
    "vertices",
    "faces",
    "skin_faces",
    "pose",
    "K",
    "landmarks3d",
    "landmarks2d",
    "displacement",
)


@dataclass(frozen=True)
class Truth:
    """One take's ground truth (see the module docstring for the fields)."""

    vertices: np.ndarray
    faces: np.ndarray
    skin_faces: np.ndarray
    pose: np.ndarray
    K: np.ndarray
    landmarks3d: np.ndarray
    landmarks2d: np.ndarray
    displacement: np.ndarray
    extra: dict

    @classmethod
    def from_arrays(cls, arrays, source: str | Path = "truth") -> Truth:
        """A Truth from a mapping of the truth keys (an open ``.npz`` or a generator's dict)."""
        missing = [k for k in _KEYS if k not in arrays]
        if missing:
            raise InputError(source, f"truth keys {missing} missing")
        return cls(
            **{k: np.asarray(arrays[k]) for k in _KEYS},
            extra={k: np.asarray(arrays[k]) for k in arrays if k not in _KEYS},
        )

    def posed_vertices(self) -> np.ndarray:
        """(N, 3) truth vertices in the take's scanner frame, mm."""
        return self.vertices @ self.pose[:3, :3].T + self.pose[:3, 3]


def read_truth(path: str | Path) -> Truth:
    """Read a truth file; a missing key is an InputError naming it."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "truth file not found")
    with np.load(path, allow_pickle=False) as data:
        return Truth.from_arrays({k: data[k] for k in data.files}, source=path)


def closest_points(vertices: np.ndarray, faces: np.ndarray, queries: np.ndarray):
    """Closest points of ``queries`` (Q, 3) on a surface.

    Returns
    -------
    face : (Q,) int64, index into ``faces``
    bary : (Q, 3) float64, barycentric weights of the face's three vertices
    distance : (Q,) float64, mm
    """
    o3d = open3d()

    scene = triangle_scene(vertices, faces)
    res = scene.compute_closest_points(
        o3d.core.Tensor(np.ascontiguousarray(queries, dtype=np.float32))
    )
    face = res["primitive_ids"].numpy().astype(np.int64)
    uv = res["primitive_uvs"].numpy().astype(np.float64)
    bary = np.column_stack([1.0 - uv.sum(axis=1), uv[:, 0], uv[:, 1]])
    point = np.einsum("qk,qkd->qd", bary, vertices[faces[face]])
    return face, bary, np.linalg.norm(point - queries, axis=1)
