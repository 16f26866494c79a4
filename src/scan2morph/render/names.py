"""The names of every stage's figures, without drawing anything.

The workflow names its figure outputs while it is parsed (``{stage}_{name}.png``); importing the
figure modules for that would load the renderer and matplotlib in every Snakemake start-up
(2.4-2.7 CPU-s of the 7 each cluster job pays). :mod:`scan2morph.render.figures` checks that its
figure functions match these names.
"""

from __future__ import annotations

from scan2morph.errors import InputError

#: Stage -> figure names, in report order.
FIGURE_NAMES: dict[str, tuple[str, ...]] = {
    "fit": ("template", "takes", "landmarks", "model"),
    "motion": ("point_pairs", "alignment", "mask", "distance", "click_noise", "visemes"),
    "morph": ("gradual", "blends", "mean", "eigen", "pca_blends", "contribution", "coefficients"),
    "modal": ("modes", "expressions", "coordinates", "reconstruction", "statistics", "synthesis"),
}


def figure_names(stage: str) -> list[str]:
    """File stems of a stage's figures, ``{stage}_{name}``, in report order.

    Raises
    ------
    InputError
        Unknown stage.
    """
    if stage not in FIGURE_NAMES:
        raise InputError("figures", f"stage: expected one of {sorted(FIGURE_NAMES)}, got {stage!r}")
    return [f"{stage}_{name}" for name in FIGURE_NAMES[stage]]
