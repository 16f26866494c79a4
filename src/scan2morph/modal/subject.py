"""One subject's modal analysis: basis of the neutral face, expression coordinates, statistics."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from scan2morph.errors import InputError
from scan2morph.modal.eigen import ModalBasis, ModalParams, modal_basis
from scan2morph.modal.project import (
    coordinate_statistics,
    project,
    reconstruct,
    reconstruction_error_curve,
    semantic_basis,
)
from scan2morph.store import paths


def subject_modal(
    neutral: np.ndarray,
    faces: np.ndarray,
    upper_face: np.ndarray,
    params: ModalParams,
    displacements: Mapping[str, np.ndarray],
    labels: Mapping[str, str],
    semantic_takes: Sequence[str],
    ks: Sequence[int],
    source: str,
    fixed: np.ndarray | None = None,
) -> tuple[ModalBasis, dict[str, np.ndarray]]:
    """Modal basis of the neutral face and everything the store keeps about it.

    Parameters
    ----------
    neutral : (V, 3) float, mm, complete
    faces : (F, 3) int
    upper_face : (V,) bool
        Vertices whose elements are thickened.
    params : ModalParams
    displacements : mapping take -> (V, 3) mm
        Expression displacement fields in the neutral frame.
    labels : mapping take -> label
    semantic_takes : sequence of str
        Expression takes inserted into the basis as semantic modes (may be empty).
    ks : sequence of int
        Numbers of modes at which the reconstruction error is reported.
    source : str
    fixed : (V,) bool, optional
        Vertices held fixed (the outer outline); default every boundary vertex.

    Returns
    -------
    basis : ModalBasis
    datasets : dict of store path -> array
    """
    basis = modal_basis(neutral, faces, params, upper_face, fixed=fixed, source=source)
    ks = sorted({int(k) for k in ks if 1 <= int(k) <= basis.n_modes} | {basis.n_modes})
    data = {
        paths.modal("frequencies_hz"): basis.frequencies_hz,
        paths.modal("modes"): basis.modes,
        paths.modal("dof_modes"): basis.dof_modes,
        paths.modal("thickness_mm"): basis.thickness_mm,
        paths.modal("fixed_vertices"): basis.fixed_vertices,
        paths.modal("reconstruction_k"): np.asarray(ks),
    }
    coords = {}
    for take, field in displacements.items():
        q = project(basis, field, source=f"{source}/{take}")
        coords[take] = q
        data[paths.expression(take, "coordinates")] = q
        data[paths.expression(take, "reconstruction_rms_mm")] = reconstruction_error_curve(
            basis, field, ks, weighting="vertex"
        )
        data[paths.expression(take, "synthesized")] = reconstruct(basis, q)
    unknown = [t for t in semantic_takes if t not in displacements]
    if unknown:
        raise InputError(
            source,
            f"modal.semantic_takes: {unknown} are not expression takes ({sorted(displacements)})",
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
