"""A subject's meshes for DCC tools (Blender, MeshLab, Maya): every mesh in the head frame.

The scanner-frame OBJs (``meshes/{take}.obj``, ``meshes/models``, ``meshes/expressions``) keep
their contract (mm, each take in its scanner's frame, invalid vertices marked and their faces
left out). Beside them, ``meshes/head/`` holds the same meshes as a DCC tool wants them, in the
glTF's head frame (:func:`scan2morph.morph.frame.head_frame`: metres, +X to the subject's left,
+Y up, +Z out of the face, origin between the eyes), every take aligned to the neutral:

- ``head/{take}.obj``: the take's mesh in correspondence with the neutral, the one the models
  are built from (:func:`correspondence`: the refined mesh, ``/takes/{take}/refine`` or where
  the takes' consensus moved it ``/takes/{take}/consensus``; the aligned template fit,
  ``/takes/{take}/align/vertices``, where the refinement did not run), textured with its own
  colour image at the points it samples;
- ``head/models/{name}.obj``: the neutral, each viseme model, blend and PCA blend (as
  ``meshes/models``), textured with the neutral's image (``neutral_texture.png``, once for
  the folder);
- ``head/expressions/{take}_measured.obj`` and ``{take}_synthesized.obj``: the neutral plus the
  expression's measured displacement and plus its modal synthesis (as ``meshes/expressions``),
  textured with the neutral's image (once for the folder).

Vertex i is template vertex i in every file, and every face is written: a vertex without a
measurement (outside the take's valid region) is placed on the hole-filled surface, the
reference mesh (the neutral) plus the harmonic interpolant of the measured vertices'
displacements from it (:func:`scan2morph.geometry.harmonic_fill`), and listed on the OBJ's
``# filled:`` line; the neutral's own filled vertices (``/neutral/filled``) are listed too.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import h5py
import numpy as np

from scan2morph.errors import InputError
from scan2morph.geometry import harmonic_fill
from scan2morph.io.obj import NEUTRAL_MATERIAL, write_material, write_obj
from scan2morph.morph.frame import apply_frame
from scan2morph.store import open_store, paths
from scan2morph.template.sample import texture_uv

#: The folder under ``results/{subject}/meshes`` that holds the head-frame meshes.
HEAD_FOLDER = "head"


def fill_from(vertices, faces, reference) -> tuple[np.ndarray, np.ndarray]:
    """Place the non-finite rows of ``vertices`` on the hole-filled surface.

    Parameters
    ----------
    vertices : (V, 3) float, mm
        A mesh of the template with NaN rows where it has no measurement.
    faces : (F, 3) int
    reference : (V, 3) float, mm, finite
        The mesh the displacements are taken from (the neutral).

    Returns
    -------
    filled : (V, 3) float64, mm, finite
        ``reference + harmonic_fill(vertices - reference)``: measured rows unchanged; a
        component of the mesh with no measured vertex keeps the reference's positions.
    missing : (V,) bool
        The rows that were filled.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    missing = ~np.isfinite(vertices).all(axis=1)
    if not missing.any():
        return vertices.copy(), missing
    moved = harmonic_fill(np.where(missing[:, None], 0.0, vertices - reference), faces, ~missing)
    moved[~np.isfinite(moved).all(axis=1)] = 0.0
    return reference + moved, missing


def write_head_obj(
    path, vertices, faces, frame, uv=None, texture=None, reference=None, filled=None
):
    """Write one mesh as a textured OBJ in the head frame (metres), every face kept.

    Parameters
    ----------
    path : path-like
        The ``.obj`` (``.mtl`` and ``.png`` beside it with ``texture``).
    vertices : (V, 3) float, mm, neutral frame
        NaN rows (no measurement) are filled from ``reference`` (:func:`fill_from`).
    faces : (F, 3) int
    frame : (4, 4) float
        Neutral frame (mm) -> head frame (m), ``/neutral/head_frame``.
    uv : (V, 2) float, optional
        Image-convention texture coordinates.
    texture : (H, W, 3) uint8 or str, optional
        The image; or a material beside the OBJ that several meshes share
        (:func:`~scan2morph.io.obj.write_material`).
    reference : (V, 3) float, mm, optional
        Required when ``vertices`` has NaN rows.
    filled : (V,) bool, optional
        Vertices already placed by a filling (e.g. ``/neutral/filled``), listed with the rows
        filled here on the ``# filled:`` line.

    Raises
    ------
    InputError
        NaN rows without a ``reference``; and what :func:`write_obj` refuses.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    missing = ~np.isfinite(vertices).all(axis=1)
    if missing.any():
        if reference is None:
            raise InputError(path, "vertices: NaN rows and no reference mesh to fill them from")
        vertices, missing = fill_from(vertices, faces, reference)
    if filled is not None:
        missing = missing | np.asarray(filled, dtype=bool)
    head = apply_frame(np.asarray(frame, dtype=np.float64), vertices)
    write_obj(path, head, faces, uv=uv, texture=texture, filled=missing, units="m")


def correspondence(h5: h5py.File, take: str) -> tuple[np.ndarray, np.ndarray | None]:
    """A take's mesh in correspondence with the neutral, as the motion stage takes it.

    Parameters
    ----------
    h5 : h5py.File
        The subject's store.
    take : str

    Returns
    -------
    vertices : (V, 3) float64, mm, neutral frame
        The refined mesh (``/takes/{take}/refine``, or ``consensus`` where the takes' consensus
        moved it; NaN where invalid), else the aligned template fit (``align/vertices``, NaN
        where the fit is invalid).
    uv : (V, 2) float64 or None
        Image-convention texture coordinates into the take's colour image of the points the
        vertices sample (the refined mesh's ``points2d``, else the fit's ``mesh/uv``).
    """
    if paths.refine(take, "vertices") in h5:
        group = paths.refined(take, h5)
        vertices = h5[group(take, "vertices")][()]
        valid = h5[group(take, "valid")][()].astype(bool)
        color = h5.get(paths.range_image(take, "color"))  # its size only: the caller reads it
        points = h5[group(take, "points2d")][()]
        uv = None if color is None else texture_uv(points, color.shape[1], color.shape[0])
    else:
        vertices = h5[paths.align(take, "vertices")][()]
        valid = h5[paths.mesh(take, "valid")][()].astype(bool)
        uv = _read(h5, paths.mesh(take, "uv"))
    return np.where(valid[:, None], vertices, np.nan), uv


def _read(h5: h5py.File, key: str):
    return h5[key][()] if key in h5 else None


def _names(h5: h5py.File, root: str, dataset: str) -> list[str]:
    if root not in h5:
        return []
    return [n for n in h5[root] if f"{root}/{n}/{dataset}" in h5]


def write_head_meshes(store: str | PathLike[str], folder: str | PathLike[str]) -> list[Path]:
    """Write every mesh of a subject's store into ``folder`` in the head frame (module docstring).

    Parameters
    ----------
    store : path-like
        ``results/{subject}/{subject}.h5``.
    folder : path-like
        ``results/{subject}/meshes/head`` (created).

    Returns
    -------
    list of Path
        The OBJs written.

    Raises
    ------
    InputError
        A store without ``/neutral/head_frame`` (the morph stage's), or one that
        :func:`scan2morph.store.open_store` refuses.
    """
    folder = Path(folder)
    written: list[Path] = []
    with open_store(store) as h5:
        frame = _read(h5, paths.neutral("head_frame"))
        if frame is None:
            raise InputError(store, f"{paths.neutral('head_frame')}: missing (run the morph stage)")
        neutral = h5[paths.neutral("vertices")][()]
        faces = h5[paths.template("faces")][()]
        takes = h5.get(paths.TAKES, {})
        kinds = {t: takes[t].attrs.get("kind") for t in takes}
        base = [t for t, k in kinds.items() if k in ("neutral", b"neutral")]
        uv0 = _read(h5, paths.mesh(base[0], "uv")) if base else None
        tex0 = _read(h5, paths.range_image(base[0], "color")) if base else None
        skin = {"uv": uv0, "texture": tex0 if uv0 is not None else None}

        shared: dict[str, dict] = {}

        def neutral_look(sub: str) -> dict:
            """The neutral's texture, written once for the folder ``sub`` and shared."""
            if skin["texture"] is None:
                return skin
            if sub not in shared:
                mtl = write_material(folder / sub, NEUTRAL_MATERIAL, skin["texture"])
                shared[sub] = {"uv": skin["uv"], "texture": mtl}
            return shared[sub]

        def write(name: str, vertices, look: dict, filled=None) -> None:
            path = folder / f"{name}.obj"
            path.parent.mkdir(parents=True, exist_ok=True)
            write_head_obj(path, vertices, faces, frame, reference=neutral, filled=filled, **look)
            written.append(path)

        for take in _names(h5, paths.TAKES, "align/vertices"):
            vertices, uv = correspondence(h5, take)
            color = _read(h5, paths.range_image(take, "color"))
            own = {"uv": uv, "texture": color} if uv is not None and color is not None else skin
            write(take, vertices, own)
        models = neutral_look("models")
        write("models/neutral", neutral, models, _read(h5, paths.neutral("filled")))
        for take in _names(h5, paths.VISEMES, "model"):
            write(f"models/{take}", h5[paths.viseme(take, "model")][()], models)
        for root, key in ((paths.BLENDS, paths.blend), (paths.PCA_BLENDS, paths.pca_blend)):
            for name in _names(h5, root, "vertices"):
                write(f"models/{name}", h5[key(name)][()], models)
        for take in _names(h5, paths.EXPRESSIONS, "displacement"):
            look = neutral_look("expressions")
            write(
                f"expressions/{take}_measured",
                neutral + h5[paths.expression(take, "displacement")][()],
                look,
            )
            synth = _read(h5, paths.expression(take, "synthesized"))
            if synth is not None:
                write(f"expressions/{take}_synthesized", neutral + synth, look)
    return written


__all__ = ["HEAD_FOLDER", "correspondence", "fill_from", "write_head_meshes", "write_head_obj"]
