"""One subject's morphable model: PCA over neutral + viseme models, named blends, exports.

Blend-shape weights name viseme *labels* (``car``, ``too``, ...); where a subject has several
takes of one label, the label's model is the mean of those takes' models.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

import numpy as np

from scan2morph.errors import InputError
from scan2morph.morph.blend import blend
from scan2morph.morph.pca import ALPHA_LIMIT, PCAModel, pca, synthesize
from scan2morph.tol import VISEMES

log = logging.getLogger(__name__)


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
        A blend naming a label the subject has no (usable) take of is left out, with a warning:
        a paper viseme (``tol.VISEMES``) it was not scanned with, or a label whose takes were
        left out. (A label no take of the sheet has is the config's error, found when the run
        starts: :func:`scan2morph.sheet_consistency.blend_label_problem`.)
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
        if missing:  # not scanned with, or its takes were left out: the blend does not apply
            paper = all(lab in VISEMES for lab in missing)
            (log.info if paper else log.warning)(
                "%s: blend %s not built: no usable take labelled %s (known: %s)",
                source, name, ", ".join(map(repr, missing)), sorted(per_label),
            )  # fmt: skip
            continue
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
#: Standard deviations sigma_k of a PCA component at weight 1 of its morph target: a 0..1 weight
#: (the range Blender's importer gives every shape key) reaches the model's alpha limit.
PCA_TARGET_SIGMAS = ALPHA_LIMIT
_SIGNS = {"pos": 1.0, "neg": -1.0}


def pca_target_name(k: int, sign: float) -> str:
    """The morph target of component ``k`` (1-based) towards ``sign`` (> 0: ``pca_k_pos``,
    < 0: ``pca_k_neg``)."""
    return f"pca_{int(k)}_{'pos' if sign > 0 else 'neg'}"


def pca_component_targets(
    model: PCAModel, neutral: np.ndarray, sigmas: float = PCA_TARGET_SIGMAS
) -> dict[str, np.ndarray]:
    """The PCA as morph targets that add up (absolute positions, exported as target - neutral).

    ``pca_mean`` is the mean (displacement ``mean - neutral``); each component has two targets,
    ``pca_{k}_pos`` = ``neutral + sigmas sigma_k e_k`` and ``pca_{k}_neg`` =
    ``neutral - sigmas sigma_k e_k`` (sigma in the model's convention). Weight 1 on ``pca_mean``
    and ``max(alpha_k, 0) / sigmas`` on ``pca_k_pos``, ``max(-alpha_k, 0) / sigmas`` on
    ``pca_k_neg`` (:func:`pca_target_weights`) give Eq. 2's ``mean + sum_k alpha_k sigma_k e_k``
    for any number of components at once, every weight within 0..1 for ``|alpha_k| <= sigmas``.

    Parameters
    ----------
    model : PCAModel
    neutral : (V, 3) float, mm
        The base mesh of the export (the neutral model S_0).
    sigmas : float
        Standard deviations at weight 1 (default :data:`PCA_TARGET_SIGMAS`, 3).

    Returns
    -------
    dict name -> (V, 3) float64, mm
        ``pca_mean``, ``pca_1_pos``, ``pca_1_neg``, ..., ``pca_K_neg`` in that order.
    """
    base = np.asarray(neutral, dtype=np.float64)
    out = {PCA_MEAN_TARGET: np.array(model.mean)}
    for i in range(model.n_components):
        step = sigmas * model.sigma[i] * model.components[i]
        out[pca_target_name(i + 1, 1)] = base + step
        out[pca_target_name(i + 1, -1)] = base - step
    return out


def pca_target_sigmas(n_components: int, sigmas: float = PCA_TARGET_SIGMAS) -> dict[str, float]:
    """Signed sigma_k per unit weight of each component target (``pca_k_pos``: ``+sigmas``,
    ``pca_k_neg``: ``-sigmas``), as the glTF's ``mesh.extras.targetSigmas`` states them."""
    return {pca_target_name(k, s): s * sigmas for k in range(1, n_components + 1) for s in (1, -1)}


def pca_target_weights(
    alphas: Sequence[float], sigmas: float = PCA_TARGET_SIGMAS
) -> dict[str, float]:
    """Morph-target weights (Blender shape-key values) that show Eq. 2 with these alphas.

    Parameters
    ----------
    alphas : sequence of float
        alpha_k in units of sigma_k, one per leading component.
    sigmas : float
        Standard deviations at weight 1 of the targets (:data:`PCA_TARGET_SIGMAS`).

    Returns
    -------
    dict name -> weight
        ``pca_mean`` 1 and, per component, ``alpha_k / sigmas`` on ``pca_k_pos`` when
        ``alpha_k >= 0``, else ``-alpha_k / sigmas`` on ``pca_k_neg`` (the other one 0.0, never
        -0.0: a weight printed or written as ``-0.0`` reads as a negative one).
    """
    out = {PCA_MEAN_TARGET: 1.0}
    for k, a in enumerate(np.asarray(alphas, dtype=np.float64).ravel(), start=1):
        # 0.0 first: max keeps the first of equal values, so alpha 0 (or -0) weighs 0.0, not -0.0
        out[pca_target_name(k, 1)] = max(0.0, float(a)) / sigmas
        out[pca_target_name(k, -1)] = max(0.0, -float(a)) / sigmas
    return out


def parse_pca_target(name: str) -> tuple[int, float] | None:
    """``(k, sign)`` of a component target's name (``pca_2_neg`` -> ``(2, -1.0)``), else None."""
    parts = name.split("_")
    if len(parts) == 3 and parts[0] == "pca" and parts[1].isdigit() and parts[2] in _SIGNS:
        return int(parts[1]), _SIGNS[parts[2]]
    return None
