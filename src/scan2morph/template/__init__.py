"""Correspondent face meshes: 2D template, thin-plate-spline fit, subdivision, sampling."""

from scan2morph.template.fit import FitRules, fit_folds, fit_map, fit_take
from scan2morph.template.mesh import (
    DEFAULT_FIDUCIAL_SET_BY_KIND,
    FIDUCIAL_SETS,
    ICP_POINTS,
    MASK_PATHS,
    Template,
    build_template,
)
from scan2morph.template.sample import (
    behind_steps,
    check_no_folds,
    sample_mesh,
    sample_range,
    texture_uv,
)
from scan2morph.template.serialize import load_template, save_template
from scan2morph.template.subdivide import subdivide, subdivide_template
from scan2morph.template.tps import TPS, noise_gain, tps_warp

__all__ = [
    "behind_steps",
    "DEFAULT_FIDUCIAL_SET_BY_KIND",
    "FIDUCIAL_SETS",
    "ICP_POINTS",
    "MASK_PATHS",
    "TPS",
    "Template",
    "build_template",
    "check_no_folds",
    "fit_folds",
    "fit_map",
    "FitRules",
    "fit_take",
    "load_template",
    "sample_mesh",
    "sample_range",
    "save_template",
    "subdivide",
    "subdivide_template",
    "texture_uv",
    "noise_gain",
    "tps_warp",
]
