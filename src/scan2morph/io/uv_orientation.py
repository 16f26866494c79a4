"""Which way up a mesh's texture coordinates run, judged from the picture.

OBJ and PLY put ``v = 0`` at the bottom row of the texture image, glTF at the top row, and the
readers convert each format's own convention. A file written against its format's convention (a
glTF whose UVs were copied from an OBJ unchanged, as the real head of our tests has them) shows
its texture upside down on the surface, and nothing in the file says so. A texture the file
carries itself was seen on the mesh by whoever made the file; a texture given in the sheet's
``texture`` column was not. For such a take the mesh is rendered through its virtual camera both
ways, and the way whose colour edges fall where the surface's own edges are (its shading lit
from the camera: lids, nostrils, lips, brows, the face's outline) is kept: the correlation of
the two images' gradient magnitudes over the face. A texture upside down puts its features
where the surface has none; a texture without features (a colour ramp) correlates neither way
and is kept as read.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from scan2morph.geometry import lambert_grey, surface_normals

#: The flipped reading is kept when its agreement exceeds the reading's by more than this.
MIN_GAIN = 0.05
#: Gaussian blur of both images before their gradients, px (a texel's resampling noise).
BLUR_PX = 1.5
#: Pixels this close to the background or a hole are left out (the silhouette's edge is in
#: the shading and the colour image alike whichever way the texture runs), px.
EDGE_MARGIN_PX = 4


@dataclass(frozen=True)
class Orientation:
    """The way a take's texture is kept.

    Attributes
    ----------
    flipped : bool
        Whether ``v`` was replaced by ``1 - v``.
    agreement : (2,) float
        :func:`texture_agreement` as read and flipped (NaN where not measurable).
    """

    flipped: bool
    agreement: tuple[float, float]

    def flip_message(self, texture: str) -> str:
        """What a flip did, for the take's log: ``texture`` is the texture's file name."""
        return (
            f"the texture {texture} lies upside down on the mesh as read (its edges agree with "
            f"the surface's {self.agreement[0]:.2f} as read, {self.agreement[1]:.2f} flipped: "
            "UVs written for another format's convention?): its v is flipped"
        )

    def as_report(self) -> dict:
        """The take report's entry: ``{"uv_flipped": bool, "uv_agreement": [as read, flipped]}``."""
        return {"uv_flipped": self.flipped, "uv_agreement": [float(a) for a in self.agreement]}


def texture_agreement(color: np.ndarray, xyz_cam: np.ndarray) -> float:
    """How well a rendered colour image's edges lie on its surface's edges.

    Parameters
    ----------
    color : (H, W, 3) uint8
        The textured render.
    xyz_cam : (H, W, 3) float
        Each pixel's surface point in the camera frame (z along the optical axis), mm; NaN on
        the background.

    Returns
    -------
    float
        The correlation coefficient, over the face's pixels, of the gradient magnitudes of the
        colour image's grey and of the surface's shading lit from the camera; NaN with fewer
        than 100 pixels or no contrast.
    """
    import cv2

    shading = lambert_grey(surface_normals(xyz_cam)[..., 2]).astype(np.float32)
    grey = np.asarray(color, dtype=np.float32).mean(axis=2)
    inside = np.isfinite(xyz_cam).all(axis=2).astype(np.uint8)
    side = 2 * EDGE_MARGIN_PX + 1
    inside = cv2.erode(inside, np.ones((side, side), np.uint8)).astype(bool)
    if inside.sum() < 100:
        return float("nan")

    def edges(image: np.ndarray) -> np.ndarray:
        smooth = cv2.GaussianBlur(image, (0, 0), BLUR_PX)
        gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0)
        gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1)
        return np.hypot(gx, gy)[inside].astype(np.float64)

    a, b = edges(grey), edges(shading)
    if a.std() == 0 or b.std() == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


def flipped_uv(mesh):
    """A copy of a textured trimesh mesh with each UV's ``v`` replaced by ``1 - v``."""
    import trimesh

    uv = np.asarray(mesh.visual.uv, dtype=np.float64).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    out = mesh.copy()
    out.visual = trimesh.visual.TextureVisuals(uv=uv, material=mesh.visual.material)
    return out


def orient_texture(
    mesh, render: Callable, to_camera: Callable[[np.ndarray], np.ndarray]
) -> tuple[np.ndarray, np.ndarray, Orientation]:
    """Render a textured mesh both ways up and keep the way its texture lies on its surface.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        With texture visuals (UVs and the texture image).
    render : callable
        ``render(mesh) -> (color (H, W, 3) uint8, depth (H, W) float mm, NaN on the
        background)`` through the take's virtual camera.
    to_camera : callable
        ``to_camera(depth) -> (H, W, 3)`` each pixel's surface point in the camera frame, mm.

    Returns
    -------
    color, depth
        The render of the way kept.
    Orientation
        Which way was kept, and both agreements.
    """
    color, depth = render(mesh)
    color_f, _ = render(flipped_uv(mesh))  # the same surface: the same depth
    xyz = to_camera(depth)
    agree = (texture_agreement(color, xyz), texture_agreement(color_f, xyz))
    flip = bool(np.isfinite(agree).all() and agree[1] > agree[0] + MIN_GAIN)
    return (color_f if flip else color), depth, Orientation(flip, agree)


__all__ = ["MIN_GAIN", "Orientation", "flipped_uv", "orient_texture", "texture_agreement"]
