"""Morphable face models: blend shapes (Eq. 1) and PCA (Eq. 2) of the Yano-Harada paper."""

from scan2morph.morph.blend import DEFAULT_BLENDS, blend
from scan2morph.morph.pca import (
    ALPHA_LIMIT,
    DEFAULT_PCA_BLENDS,
    PCAModel,
    contribution_rates,
    pca,
    pca_tables,
    project,
    synthesize,
)

__all__ = [
    "ALPHA_LIMIT",
    "DEFAULT_BLENDS",
    "DEFAULT_PCA_BLENDS",
    "PCAModel",
    "blend",
    "contribution_rates",
    "pca",
    "pca_tables",
    "project",
    "synthesize",
]
