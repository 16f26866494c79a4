"""Morph: PCA over the neutral and the viseme models (Yano & Harada 2009, sec. 5, Tables 1-3),
named blend shapes (Eq. 1) and PCA blends (Eq. 2), and their exports (glTF, OBJ)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from scan2morph.geometry import TexturedMesh
from scan2morph.io import write_glb, write_material, write_obj
from scan2morph.io.gltf import MorphTargets
from scan2morph.io.obj import NEUTRAL_MATERIAL
from scan2morph.morph import pca_tables
from scan2morph.morph.frame import HEAD_FRAME_NAME, head_frame
from scan2morph.morph.pca import SIGMA_CONVENTIONS, PCAModel
from scan2morph.morph.subject import (
    PCA_MEAN_TARGET,
    parse_pca_target,
    pca_component_targets,
    pca_target_sigmas,
    subject_morph,
)
from scan2morph.stages.part import Part, Subject, need
from scan2morph.stages.quality import modelled
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template

#: Config sections this stage reads (``template`` for the subdivision level).
SECTIONS = ("morph", "template")
#: Why a subject without viseme takes gets no PCA or blends (recorded in the store).
NO_VISEMES = "no viseme takes: no blend shapes or PCA (the glTF and OBJ hold the neutral only)"


@dataclass(frozen=True)
class Params:
    """Morph parameters.

    Attributes
    ----------
    levels : int
        Template subdivisions.
    blends : mapping
        Named blend shapes (Eq. 1): name -> weights by viseme label (``morph.blends``).
    pca_blends : mapping
        Named PCA blends (Eq. 2): name -> alphas (``morph.pca_blends``).
    alpha_limit : float
        Largest PCA alpha allowed, in sigmas (``morph.alpha_limit``).
    sigma : str
        The unit of the alphas (a convention of :data:`~scan2morph.morph.pca.SIGMA_CONVENTIONS`).
    """

    levels: int
    blends: Mapping
    pca_blends: Mapping
    alpha_limit: float
    sigma: str = "sample"

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``morph`` and ``template``."""
        m = config["morph"]
        levels = int(config["template"]["subdivision_levels"])
        return cls(levels, m["blends"], m["pca_blends"], m["alpha_limit"], m.get("sigma", "sample"))


def pca_datasets(model: PCAModel) -> dict[str, np.ndarray]:
    """The ``/pca`` group of the store (``sigma``: the unit of Eq. 2's alphas, mm, in the
    convention ``sigma_convention`` names)."""
    return {
        paths.pca("mean"): model.mean,
        paths.pca("components"): model.components,
        paths.pca("eigenvalues"): model.eigenvalues,
        paths.pca("cr"): model.cr,
        paths.pca("ccr"): model.ccr,
        paths.pca("coefficients"): model.coefficients,
        paths.pca("takes"): np.asarray(model.names, dtype=object),
        paths.pca("sigma"): model.sigma,
        paths.pca("sigma_convention"): model.sigma_convention,
    }


def _target_notes(model: PCAModel | None, visemes) -> dict[str, str]:
    """What each glTF morph target is (``mesh.extras.targetNotes``)."""
    notes = {t: "viseme model - neutral" for t in visemes}
    if model is not None:
        notes[PCA_MEAN_TARGET] = "PCA mean - neutral (weight 1 with the pca_k_pos/neg for Eq. 2)"
        convention = SIGMA_CONVENTIONS[model.sigma_convention]
        for name, s in pca_target_sigmas(model.n_components).items():
            k, _ = parse_pca_target(name)
            notes[name] = (
                f"{s:+g} sigma_{k} e_{k} (weight w: alpha_{k} = {s:+g} w); sigma: {convention}"
            )
    return notes


def run(
    template: Template, subject: Subject, data: Mapping[str, np.ndarray], params: Params
) -> Part:
    """PCA, blends and export shapes of one subject.

    Parameters
    ----------
    template, subject
        The base template and the subject (the contract of :mod:`scan2morph.stages`).
    data : mapping store path -> array
        The motion part, the neutral's fit part (``mesh/uv``) and repair part (``range/color``).
    params : Params

    Returns
    -------
    Part
        ``/neutral/head_frame`` (neutral frame mm -> head frame m, the glTF's frame),
        ``/pca/*`` (with ``sigma`` and ``sigma_convention``), ``/blends/{name}/vertices``,
        ``/pca_blends/{name}/vertices`` (mm); ``files``: the PCA tables (``eigen``,
        ``coefficients``), the ``faces``, ``uv`` and ``texture`` of the neutral, the glTF morph
        ``targets`` (a :class:`~scan2morph.io.gltf.MorphTargets` carrying the head frame: one
        per viseme, ``pca_mean`` and two per PCA component, ``pca_k_pos`` and ``pca_k_neg`` at
        +-3 sigma_k, see :func:`~scan2morph.morph.subject.pca_component_targets`) and the OBJ
        ``shapes``. A
        subject without visemes gets the head frame only, empty tables, the neutral alone as its
        shapes and glTF, and the reason under ``/skipped`` (attribute ``morph``).
    """
    subject = modelled(subject, data)
    name, neutral = subject.name, subject.neutral
    faces = subdivide_template(template, params.levels).faces
    base = need(data, paths.neutral("vertices"), name)
    frame = head_frame(base, template.named, source=f"{name}/head frame")
    frame_data = {paths.neutral("head_frame"): frame}
    files = {
        "eigen": pd.DataFrame(columns=["component", "eigenvalue", "cr", "ccr"]),
        "coefficients": pd.DataFrame(columns=["take"]),
        "faces": faces,
        "uv": need(data, paths.mesh(neutral, "uv"), name),
        "texture": need(data, paths.range_image(neutral, "color"), name),
        "targets": MorphTargets(frame=frame, frame_name=HEAD_FRAME_NAME),
        "shapes": {"neutral": base},
    }
    if not subject.visemes:
        return Part(frame_data, attrs={paths.SKIPPED: {"morph": NO_VISEMES}}, files=files)
    models = {t: need(data, paths.viseme(t, "model"), name) for t in subject.visemes}
    model, blends, pca_shapes = subject_morph(
        base,
        models,
        subject.labels,
        params.blends,
        params.pca_blends,
        params.alpha_limit,
        source=name,
        sigma=params.sigma,
    )
    datasets = frame_data | pca_datasets(model)
    datasets |= {paths.blend(k): v for k, v in blends.items()}
    datasets |= {paths.pca_blend(k): v for k, v in pca_shapes.items()}
    eigen, coefficients = pca_tables(model)
    files |= {
        "eigen": pd.DataFrame(eigen),
        "coefficients": pd.DataFrame(coefficients),
        "targets": MorphTargets(
            models | pca_component_targets(model, base),
            frame=frame,
            frame_name=HEAD_FRAME_NAME,
            notes=_target_notes(model, models),
            sigmas=pca_target_sigmas(model.n_components),
        ),
        "shapes": {"neutral": base, **models, **blends, **pca_shapes},
    }
    attrs = {paths.PCA: {"sigma_convention": model.sigma_convention}}
    return Part(datasets, attrs=attrs, files=files)


def write_files(part: Part, eigen: str, coefficients: str, glb: str, models: str) -> None:
    """Write the PCA tables (TSV with their column dictionaries), the glTF with one morph target
    per viseme, ``pca_mean`` and two per PCA component, and one OBJ per model and blend into the
    folder ``models``."""
    from scan2morph.tables import PCA_COEFFICIENTS, PCA_EIGENVALUES, write_table

    f = part.files
    write_table(eigen, f["eigen"], PCA_EIGENVALUES)
    write_table(coefficients, f["coefficients"], PCA_COEFFICIENTS)
    base = f["shapes"]["neutral"]
    write_glb(glb, TexturedMesh(base, f["faces"], f["uv"], f["texture"]), f["targets"])
    folder = Path(models)
    folder.mkdir(parents=True, exist_ok=True)
    skin = write_material(folder, NEUTRAL_MATERIAL, f["texture"])  # one texture for every model
    for name, shape in f["shapes"].items():
        write_obj(folder / f"{name}.obj", shape, f["faces"], uv=f["uv"], texture=skin)
