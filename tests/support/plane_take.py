"""A textured plane seen as a take (640 x 480, or smaller): the refinement's scenes with a known
answer."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

#: Lateral size of one pixel on the plane, mm.
PIXEL_MM = 0.7
#: The plane takes' images, px (height, width): the scanner's, and half of it (for tests whose
#: claim does not depend on the size).
FULL, HALF = (480, 640), (240, 320)


def skin_texture(shape, seed, blob_px=1.5, contrast=25.0):
    """A skin-like random texture: blurred noise, grey levels around 150."""
    rng = np.random.default_rng(seed)
    t = gaussian_filter(rng.standard_normal(shape), blob_px)
    return 150.0 + contrast * t / t.std()


def plane_take(
    template, texture_seed, config, depth_slope=(0.05, -0.03), landmarks=None, size=FULL
):
    """A take ``t`` of a tilted plane (640 x 480) with a random texture and landmarks on it.

    Parameters
    ----------
    template : Template
    texture_seed : int
        The skin texture's seed (the same seed: the same skin).
    config : dict
        The repository's config (the fit's fiducial set and rules).
    depth_slope : (2,) float
        The plane's depth per pixel along x and y, mm (``PIXEL_MM`` laterally: 1.6 along x is
        66 degrees to the image plane).
    landmarks : (68, 2) float, optional
        The take's landmarks, px (default: :func:`plane_landmarks`).
    size : (2,) int
        The image's height and width, px; the plane's centre stays at the image's centre, its
        pixels ``PIXEL_MM`` wide.

    Returns
    -------
    dict
        Store path -> array of the take's repair, landmarks, fit and (identity) align parts.
    """
    from scan2morph.align import transform_points
    from scan2morph.stages import fit
    from scan2morph.store import paths
    from scan2morph.template import fit_take

    h, w = size
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    sx, sy = depth_slope
    origin = [-PIXEL_MM * w / 2, -PIXEL_MM * h / 2, 1000.0]
    plane = np.array([[PIXEL_MM, 0.0, sx], [0.0, PIXEL_MM, sy], origin])
    xyz = np.stack([x, y, np.ones_like(x)], axis=-1) @ plane
    if landmarks is None:
        landmarks = plane_landmarks(template, size)
    grey = np.clip(skin_texture((h, w), texture_seed), 0, 255).astype(np.uint8)
    params = fit.Params.from_config(config)
    mesh = fit_take(
        template, landmarks, xyz, fiducial_set=params.fiducial_set("viseme"), rules=params.rules
    )
    return {
        paths.range_image("t", "xyz"): xyz,
        paths.range_image("t", "color"): np.repeat(grey[..., None], 3, axis=-1),
        paths.landmarks("t"): landmarks,
        paths.mesh("t", "valid"): mesh["valid"],
        paths.mesh("t", "points2d"): mesh["points2d"],
        paths.align("t", "transform"): np.eye(4),
        paths.align("t", "vertices"): transform_points(np.eye(4), mesh["vertices"]),
    }


def plane_landmarks(template, size=FULL):
    """(68, 2) the template's iBUG points on a plane take of ``size`` (height, width), px: 70 px
    a unit about (320, 230) at 640 x 480, scaled with the width."""
    scale = size[1] / 640.0
    return scale * (np.array([320.0, 230.0]) + 70.0 * template.ibug_xy)


def renamed(data, take, old="t"):
    """``data`` of take ``old`` as take ``take``'s."""
    return {k.replace(f"/takes/{old}/", f"/takes/{take}/"): v for k, v in data.items()}
