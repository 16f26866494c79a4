"""One subject's modal analysis: basis of the neutral face, expression coordinates, statistics."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals
from scan2morph.modal.basis import ModalBasis, ModalParams, modal_basis
from scan2morph.modal.boundary import OutlineChoice
from scan2morph.modal.project import (
    coordinate_statistics,
    project,
    reconstruct,
    reconstruction_split,
    semantic_basis,
)
from scan2morph.store import paths


def rms_length(field: np.ndarray, where: np.ndarray) -> float:
    """RMS over the vertices in ``where`` (with a finite value) of the length of a (V, 3)
    field, mm; NaN when there is none."""
    f = np.asarray(field, dtype=np.float64)[np.asarray(where, dtype=bool)]
    f = f[np.isfinite(f).all(axis=1)]
    return float(np.sqrt(np.mean(np.sum(f**2, axis=1)))) if len(f) else float("nan")


@dataclass(frozen=True)
class NeutralShell:
    """The neutral face a subject's modal basis is built on.

    Attributes
    ----------
    vertices : (V, 3) float, mm, complete
    faces : (F, 3) int
    upper_face : (V,) bool
        Vertices whose elements are thickened.
    normals : (V, 3) float, optional
        Unit vertex normals (default: computed from ``vertices`` and ``faces``), for the normal
        / tangential split of the reconstruction error.
    """

    vertices: np.ndarray
    faces: np.ndarray
    upper_face: np.ndarray
    normals: np.ndarray | None = None


@dataclass(frozen=True)
class ExpressionFields:
    """A subject's expressions and how their modal reconstruction is measured.

    Attributes
    ----------
    displacements : mapping take -> (V, 3) mm
        Expression displacement fields in the neutral frame.
    labels : mapping take -> label
    semantic_takes : sequence of str
        Expression takes inserted into the basis as semantic modes (may be empty).
    ks : sequence of int
        Numbers of modes at which the reconstruction error is reported.
    target_mm : float
        RMS reconstruction error (mm) whose mode count is reported (``modes_to_target``).
    """

    displacements: Mapping[str, np.ndarray]
    labels: Mapping[str, str]
    semantic_takes: Sequence[str] = ()
    ks: Sequence[int] = ()
    target_mm: float = 0.5


def subject_modal(
    shell: NeutralShell,
    params: ModalParams,
    expressions: ExpressionFields,
    source: str,
    fixed: np.ndarray | OutlineChoice | None = None,
    basis: ModalBasis | None = None,
) -> tuple[ModalBasis, dict[str, np.ndarray]]:
    """Modal basis of the neutral face and everything the store keeps about it.

    Parameters
    ----------
    shell : NeutralShell
        The neutral face, its thickened part and its normals.
    params : ModalParams
    expressions : ExpressionFields
        The expression fields, their labels, the semantic takes and the reconstruction's
        reporting (mode counts, target RMS).
    source : str
    fixed : (V,) bool or OutlineChoice, optional
        Vertices held fixed (the outer outline, or the part of it
        :func:`scan2morph.modal.boundary.still_outline` chose, whose outline and measured
        outline motion are then stored too); default every boundary vertex.
    basis : ModalBasis, optional
        The natural basis, when the caller built it (with more of the physics than
        ``params``, ``shell.upper_face`` and ``fixed`` say); its fixed vertices replace
        ``fixed``'s mask.

    Returns
    -------
    basis : ModalBasis
    datasets : dict of store path -> array
    """
    neutral, faces, upper_face, normals = (
        shell.vertices,
        shell.faces,
        shell.upper_face,
        shell.normals,
    )
    e = expressions
    displacements, labels, semantic_takes = e.displacements, e.labels, e.semantic_takes
    ks, target_mm = e.ks, e.target_mm
    choice = fixed if isinstance(fixed, OutlineChoice) else None
    mask = choice.fixed if choice is not None else fixed
    if basis is None:
        basis = modal_basis(neutral, faces, params, upper_face, fixed=mask, source=source)
    ks = sorted({int(k) for k in ks if 1 <= int(k) <= basis.n_modes} | {basis.n_modes})
    if normals is None:
        normals = vertex_normals(neutral, faces)
    data = {
        paths.modal("frequencies_hz"): basis.frequencies_hz,
        paths.modal("modes"): basis.modes,
        paths.modal("dof_modes"): basis.dof_modes,
        paths.modal("thickness_mm"): basis.thickness_mm,
        paths.modal("fixed_vertices"): basis.fixed_vertices,
        paths.modal("reconstruction_k"): np.asarray(ks),
        paths.modal("reconstruction_target_mm"): np.float64(target_mm),
    }
    outline = basis.fixed_vertices if choice is None else choice.outline
    if choice is not None:
        data[paths.modal("outline_vertices")] = choice.outline
        data[paths.modal("outline_motion_mm")] = choice.motion_mm
    coords = {}
    for take, field in displacements.items():
        where = f"{source}/{take}"
        coords[take] = project(basis, field, source=where)
        data |= _expression_datasets(
            basis, take, field, coords[take], (normals, ks, target_mm, outline), where
        )
    unknown = [t for t in semantic_takes if t not in displacements]
    if unknown:
        raise InputError(
            source,
            f"semantic_takes: {unknown} are not expression takes ({sorted(displacements)})",
        )
    if semantic_takes:
        sem = semantic_basis(
            basis, [displacements[t] for t in semantic_takes], list(semantic_takes), source=source
        )
        data[paths.modal("semantic/names")] = np.asarray(sem.names, dtype=object)
        data[paths.modal("semantic/modes")] = sem.modes
        for take, field in displacements.items():
            data[paths.expression(take, "semantic_coordinates")] = project(
                sem, field, source=f"{source}/{take}"
            )
    if coords:
        for label, stats in coordinate_statistics(coords, {t: labels[t] for t in coords}).items():
            data[paths.modal_statistics(label, "mean")] = stats.mean
            data[paths.modal_statistics(label, "std")] = stats.std
            data[paths.modal_statistics(label, "takes")] = np.asarray(stats.takes, dtype=object)
    return basis, data


def _expression_datasets(basis, take: str, field, q, measure: tuple, source: str) -> dict:
    """One expression's coordinates ``q``, its reconstruction against K (total, normal and
    tangential parts, modes to the target), its motion on the outline and on the clamped
    vertices, and its modal synthesis. ``measure`` is (normals, ks, target_mm, outline)."""
    normals, ks, target_mm, outline = measure
    split = reconstruction_split(basis, field, normals, ks, target_mm, source=source)
    return {
        paths.expression(take, "coordinates"): q,
        paths.expression(take, "reconstruction_rms_mm"): split.total_mm,
        paths.expression(take, "reconstruction_normal_rms_mm"): split.normal_mm,
        paths.expression(take, "reconstruction_tangential_rms_mm"): split.tangential_mm,
        paths.expression(take, "modes_to_target"): np.float64(split.modes_to_target),
        paths.expression(take, "outline_rms_mm"): np.float64(rms_length(field, outline)),
        paths.expression(take, "clamped_rms_mm"): np.float64(
            rms_length(field, basis.fixed_vertices)
        ),
        paths.expression(take, "synthesized"): reconstruct(basis, q),
    }
