"""One subject's morphable model: PCA over neutral + viseme models, named blends, exports.

Blend-shape weights name viseme *labels* (``car``, ``too``, ...); where a subject has several
takes of one label, the label's model is the mean of those takes' models.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from scan2morph.errors import InputError
from scan2morph.morph.blend import blend
from scan2morph.morph.pca import PCAModel, pca, synthesize
from scan2morph.tol import VISEMES


def label_models(
    models: Mapping[str, np.ndarray], labels: Mapping[str, str]
) -> dict[str, np.ndarray]:
    """Mean model per viseme label (takes of one label averaged)."""
    out: dict[str, list[np.ndarray]] = {}
    for take, model in models.items():
        out.setdefault(labels[take], []).append(model)
    return {label: np.mean(shapes, axis=0) for label, shapes in out.items()}


def subject_morph(
    neutral: np.ndarray,
    models: Mapping[str, np.ndarray],
    labels: Mapping[str, str],
    blends: Mapping[str, Mapping[str, float]],
    pca_blends: Mapping[str, Sequence[float]],
    alpha_limit: float,
    source: str,
    sigma: str = "sample",
) -> tuple[PCAModel, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """PCA and named blends of one subject.

    Parameters
    ----------
    neutral : (V, 3) float, mm, complete (no NaN)
        The base model S_0.
    models : mapping take -> (V, 3)
        Viseme models S_i (neutral + processed motion), in the neutral frame.
    labels : mapping take -> label
    blends : mapping name -> (label -> weight)
        Blend shapes (Eq. 1) to build.
    pca_blends : mapping name -> alphas
        PCA blends (Eq. 2) to build; a blend with non-zero alphas beyond the model's components
        (a subject with few takes) is left out.
    alpha_limit : float
    source : str
        Subject label for messages.
    sigma : ``"sample"`` or ``"paper"``
        The sigma convention of Eq. 2 (config ``morph.sigma``, :data:`~scan2morph.morph.pca.SIGMA_CONVENTIONS`).

    Returns
    -------
    model : PCAModel
        Over ``["neutral", *models]`` in that order.
    blend_shapes : dict name -> (V, 3)
        Blends naming a paper viseme (``tol.VISEMES``) the subject has no take of are left out;
        any other unknown label is an error.
    pca_shapes : dict name -> (V, 3)
    """
    if not models:
        raise InputError(source, "no viseme takes: the morphable model needs at least one viseme")
    model = pca(
        [neutral, *models.values()],
        names=["neutral", *models],
        sigma=sigma,
        source=f"{source}/pca",
    )
    per_label = label_models(models, labels)
    blend_shapes = {}
    for name, weights in blends.items():
        missing = [lab for lab in weights if lab not in per_label]
        if missing and all(lab in VISEMES for lab in missing):
            continue  # a paper viseme this subject was not scanned with: the blend does not apply
        blend_shapes[name] = blend(
            neutral, per_label, dict(weights), source=f"{source}/morph.blends.{name}"
        )
    pca_shapes = {}
    for name, alpha in pca_blends.items():
        a = np.asarray(alpha, dtype=float)
        if np.any(a[model.n_components :] != 0):
            continue  # needs more components than this subject's few takes give: does not apply
        pca_shapes[name] = synthesize(
            model,
            a[: model.n_components],
            alpha_limit=alpha_limit,
            source=f"{source}/morph.pca_blends.{name}",
        )
    return model, blend_shapes, pca_shapes


#: Name of the morph target that moves the neutral to the PCA mean.
PCA_MEAN_TARGET = "pca_mean"


def pca_component_targets(model: PCAModel, neutral: np.ndarray) -> dict[str, np.ndarray]:
    """The PCA as morph targets that add up (absolute positions, exported as target - neutral).

    ``pca_mean`` is the mean (displacement ``mean - neutral``) and ``pca_{k}`` is
    ``neutral + sigma_k e_k`` (displacement ``sigma_k e_k``, sigma in the model's convention), so
    that weights ``1`` on ``pca_mean`` and ``alpha_k`` on ``pca_{k}`` give Eq. 2's
    ``mean + sum_k alpha_k sigma_k e_k`` exactly, for any number of components at once.

    Parameters
    ----------
    model : PCAModel
    neutral : (V, 3) float, mm
        The base mesh of the export (the neutral model S_0).

    Returns
    -------
    dict name -> (V, 3) float64, mm
        ``pca_mean``, ``pca_1``, ..., ``pca_K`` in that order.
    """
    base = np.asarray(neutral, dtype=np.float64)
    out = {PCA_MEAN_TARGET: np.array(model.mean)}
    for i in range(model.n_components):
        out[f"pca_{i + 1}"] = base + model.sigma[i] * model.components[i]
    return out
