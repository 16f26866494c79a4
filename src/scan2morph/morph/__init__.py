"""Morphable face models: blend shapes (Eq. 1) and PCA (Eq. 2) of the Yano-Harada paper."""

from scan2morph.morph.blend import DEFAULT_BLENDS, blend
from scan2morph.morph.frame import head_frame
from scan2morph.morph.pca import (
    ALPHA_LIMIT,
    DEFAULT_PCA_BLENDS,
    SIGMA_CONVENTIONS,
    PCAModel,
    contribution_rates,
    pca,
    pca_tables,
    project,
    sigmas,
    synthesize,
)

__all__ = [
    "ALPHA_LIMIT",
    "DEFAULT_BLENDS",
    "DEFAULT_PCA_BLENDS",
    "PCAModel",
    "SIGMA_CONVENTIONS",
    "blend",
    "contribution_rates",
    "head_frame",
    "pca",
    "pca_tables",
    "project",
    "sigmas",
    "synthesize",
]
