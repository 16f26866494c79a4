"""Range images and head turns for the tests of takes seen from another place than their neutral
(:func:`scan2morph.stages.take_mesh.view_turn`): a ball seen by a pinhole camera, a turn about a
point, the middle of a take's points."""

from __future__ import annotations

import numpy as np

from scan2morph.stages.take_mesh import grid_middle
from scan2morph.store import paths


def middle(data, take: str) -> np.ndarray:
    """(3,) the middle of a take's range points, mm: the face
    :func:`scan2morph.stages.take_mesh.view_turn` measures the turn at."""
    return grid_middle(data[paths.range_image(take, "xyz")])


def yaw_about(deg: float, about: np.ndarray) -> np.ndarray:
    """(4, 4) a turn of ``deg`` degrees about the image's vertical axis through ``about`` (mm)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    t = np.eye(4)
    t[:3, :3] = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
    t[:3, 3] = about - t[:3, :3] @ about
    return t


def ball_grid(transform: np.ndarray | None = None) -> np.ndarray:
    """(60, 80, 3) a range image of a ball 120 mm across, 700 mm in front of a pinhole camera at
    the origin (300 px focal length), its points moved by ``transform`` (4, 4; None: not moved);
    NaN off the ball."""
    transform = np.eye(4) if transform is None else transform
    v, u = np.mgrid[0:60, 0:80].astype(np.float64)
    rays = np.stack([(u - 39.5) / 300.0, (v - 29.5) / 300.0, np.ones_like(u)], axis=-1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    centre, radius = np.array([0.0, 0.0, 700.0]), 60.0
    b = rays @ centre
    disc = b**2 - (centre @ centre - radius**2)
    t = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0.0)), np.nan)
    points = rays * t[..., None]
    return points @ transform[:3, :3].T + transform[:3, 3]
