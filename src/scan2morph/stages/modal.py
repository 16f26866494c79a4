"""Modal: the shell finite-element modal basis of the neutral face, (K - w^2 M) Q = 0, and the
expressions' modal coordinates, reconstruction errors and statistics (modal-analysis paper)."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from scan2morph.io import write_obj
from scan2morph.modal import ModalParams, ShellMaterial
from scan2morph.modal.boundary import OutlineChoice, still_outline
from scan2morph.modal.subject import subject_modal
from scan2morph.stages.part import Part, Subject, need
from scan2morph.stages.quality import modelled
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template
from scan2morph.template.regions import upper_face

#: Config sections this stage reads (``template`` for the subdivision level).
SECTIONS = ("modal", "template")
#: Why a subject without expression takes gets the modal basis only (recorded in the store).
NO_EXPRESSIONS = "no expression takes: the modal basis only, no modal coordinates"
#: Rows of the reconstruction table: part of the error -> its dataset per expression.
RECONSTRUCTION_PARTS = {
    "total": "reconstruction_rms_mm",
    "normal": "reconstruction_normal_rms_mm",
    "tangential": "reconstruction_tangential_rms_mm",
}
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Modal parameters.

    Attributes
    ----------
    levels : int
        Template subdivisions.
    modal : ModalParams
        Modes, shell thickness (mm), stiffening, material, threads, seed.
    stiff_above : str
        Named point above which the face is stiffened (``modal.stiff_above``).
    semantic_labels : list of str
        Expression labels whose first take becomes a semantic mode.
    reconstruction_k : list of int
        Numbers of modes at which the reconstruction error is reported.
    fixed_outline : {"still", "all"}
        Outline vertices clamped: those the takes do not move (``still``) or all (the paper).
    still_mm : float
        Median displacement over the takes below which an outline vertex is still, mm.
    min_fixed_share : float
        Share of the outline clamped at least.
    target_rms_mm : float
        Reconstruction error whose mode count is reported, mm.
    """

    levels: int
    modal: ModalParams
    stiff_above: str
    semantic_labels: list
    reconstruction_k: list
    fixed_outline: str = "still"
    still_mm: float = 1.0
    min_fixed_share: float = 0.25
    target_rms_mm: float = 0.5

    @classmethod
    def from_config(cls, modal: Mapping, template: Mapping, threads: int = 1) -> Params:
        """From the config sections ``modal`` and ``template`` and the job's threads."""
        params = ModalParams(
            n_modes=modal["modes"],
            thickness_mm=modal["thickness_mm"],
            upper_thickness_factor=modal["stiff_factor"],
            material=ShellMaterial(
                modal["youngs_modulus_mpa"], modal["poisson_ratio"], modal["density_t_per_mm3"]
            ),
            threads=threads,
            seed=modal["seed"],
        )
        return cls(
            int(template["subdivision_levels"]),
            params,
            modal["stiff_above"],
            list(modal["semantic_labels"]),
            list(modal["reconstruction_k"]),
            str(modal.get("fixed_outline", "still")),
            float(modal.get("still_mm", 1.0)),
            float(modal.get("min_fixed_share", 0.25)),
            float(modal.get("target_rms_mm", 0.5)),
        )


def semantic_takes(subject: Subject, labels: list) -> list[str]:
    """The first expression take of each semantic label the subject has, in label order."""
    expressions = subject.expressions
    return [
        next(t for t in expressions if subject.labels[t] == lab)
        for lab in labels
        if any(subject.labels[t] == lab for t in expressions)
    ]


def outline_choice(
    fine: Template,
    subject: Subject,
    data: Mapping[str, np.ndarray],
    fields: Mapping[str, np.ndarray],
    params: Params,
) -> OutlineChoice:
    """The outline vertices the shell model clamps (:func:`still_outline` on the subdivided
    template's outer loop, from the visemes' motion and the expressions' ``fields``).

    The paper fixes the face's outline; the mouth loop (the lips) stays free. With
    ``fixed_outline: still``, only the part of the outline that the takes do not move.
    """
    moved = [
        data[paths.viseme(t, "motion")]
        for t in subject.visemes
        if paths.viseme(t, "motion") in data
    ]
    return still_outline(
        fine.boundary,
        [*moved, *fields.values()],
        fine.n_vertices,
        params.fixed_outline,
        params.still_mm,
        params.min_fixed_share,
        source=subject.name,
    )


def run(
    template: Template, subject: Subject, data: Mapping[str, np.ndarray], params: Params
) -> Part:
    """Modal basis and expression coordinates of one subject.

    Parameters
    ----------
    template, subject
        The base template and the subject (the contract of :mod:`scan2morph.stages`).
    data : mapping store path -> array
        The motion part (``/neutral/vertices``, ``/expressions/{take}/displacement``, and
        ``/visemes/{take}/motion``, which with the expressions tells which outline vertices
        stay still).
    params : Params

    Returns
    -------
    Part
        ``/modal/*`` and ``/expressions/{take}/coordinates|reconstruction_rms_mm|
        reconstruction_normal_rms_mm|reconstruction_tangential_rms_mm|modes_to_target|
        outline_rms_mm|clamped_rms_mm|synthesized|semantic_coordinates``; ``files``: the ``coordinates`` and ``reconstruction`` tables, and
        the measured and synthesised expression ``meshes`` with their ``faces``.
    """
    subject = modelled(subject, data)
    fine = subdivide_template(template, params.levels)
    name = subject.name
    base = need(data, paths.neutral("vertices"), name)
    fields = {t: need(data, paths.expression(t, "displacement"), name) for t in subject.expressions}
    outline = outline_choice(fine, subject, data, fields, params)
    log.info(
        "%s: %d of %d outline vertices clamped (fixed_outline: %s)",
        name,
        int(outline.fixed.sum()),
        int(outline.outline.sum()),
        params.fixed_outline,
    )
    basis, datasets = subject_modal(
        base,
        fine.faces,
        upper_face(fine, params.stiff_above),
        params.modal,
        fields,
        subject.labels,
        semantic_takes(subject, params.semantic_labels),
        params.reconstruction_k,
        source=name,
        fixed=outline,
        target_mm=params.target_rms_mm,
    )
    freq = basis.frequencies_hz
    log.info("%s: %d modes, %.1f to %.1f Hz", name, basis.n_modes, freq[0], freq[-1])
    takes = subject.expressions
    coords = {t: datasets[paths.expression(t, "coordinates")] for t in takes}
    columns = [f"q{i + 1}" for i in range(basis.n_modes)]
    ks = datasets[paths.modal("reconstruction_k")]
    rows = []
    for t in takes:  # one row per expression and part of the error
        for part, key in RECONSTRUCTION_PARTS.items():
            rows.append(
                {"take": t, "part": part}
                | dict(zip([f"K={k}" for k in ks], datasets[paths.expression(t, key)], strict=True))
                | {"modes_to_target": datasets[paths.expression(t, "modes_to_target")]}
            )
    meshes = {}
    for t in takes:  # each expression as measured and as synthesised from its coordinates
        meshes[f"{t}_measured"] = base + fields[t]
        meshes[f"{t}_synthesized"] = base + datasets[paths.expression(t, "synthesized")]
    files = {
        "coordinates": pd.DataFrame.from_dict(coords, orient="index", columns=columns),
        "reconstruction": pd.DataFrame(
            rows, columns=["take", "part", *[f"K={k}" for k in ks], "modes_to_target"]
        ),
        "faces": fine.faces,
        "meshes": meshes,
    }
    attrs = {} if takes else {paths.SKIPPED: {"modal_coordinates": NO_EXPRESSIONS}}
    return Part(datasets, attrs=attrs, files=files)


def write_files(part: Part, coordinates: str, reconstruction: str, meshes: str) -> None:
    """Write the coordinate and reconstruction tables (TSV with their column dictionaries, one
    row per expression take) and the measured and synthesised expression meshes (OBJ) into the
    folder ``meshes``."""
    from scan2morph.tables import MODAL_COORDINATES, MODAL_RECONSTRUCTION, write_table

    f = part.files
    coords = f["coordinates"].rename_axis("take").reset_index()
    write_table(coordinates, coords, MODAL_COORDINATES)
    write_table(reconstruction, f["reconstruction"], MODAL_RECONSTRUCTION, float_format="%.4f")
    folder = Path(meshes)
    folder.mkdir(parents=True, exist_ok=True)
    for name, vertices in f["meshes"].items():
        write_obj(folder / f"{name}.obj", vertices, f["faces"])
