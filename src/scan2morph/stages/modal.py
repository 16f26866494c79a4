"""Modal: the shell finite-element modal basis of the neutral face, (K - w^2 M) Q = 0, and the
expressions' modal coordinates, reconstruction errors and statistics (modal-analysis paper)."""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from scan2morph.errors import InputError
from scan2morph.io import write_material, write_obj
from scan2morph.io.obj import NEUTRAL_MATERIAL
from scan2morph.modal import Held, ModalBasis, ModalParams, ShellMaterial
from scan2morph.modal.boundary import POLICIES, OutlineChoice, still_outline, still_skin
from scan2morph.modal.subject import ExpressionFields, NeutralShell, subject_modal
from scan2morph.stages.part import Part, Subject, need
from scan2morph.stages.quality import modelled
from scan2morph.store import paths
from scan2morph.template import Template, subdivide_template
from scan2morph.template.regions import stable_face, upper_face

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

#: The physics of the natural basis by preset (config ``modal.preset``); a ``modal.*`` key of
#: the same name overrides one value. ``paper``: the modal-analysis paper's steel shell, 1 mm,
#: three times thicker above the nose tip, whole outline clamped. ``clamped_still``: the same
#: shell clamped only where the takes leave the outline still (this pipeline's basis before
#: ``skin``). ``skin``: a pre-tensioned skin on an elastic foundation: a 1 mm membrane (no
#: shell: E = 0, the rotations held) under an isotropic tension of 1 N/mm, on tissue that
#: resists normal motion (0.01 N/mm^3) and, where every expression leaves the skin still
#: (``tether_region: still``, ``still_from: expressions``, within ``still_mm``), ties it to the
#: bone against sliding (0.1 N/mm^3) and normal motion (another 0.1 N/mm^3), its mass per area
#: 1.4 times higher in the mimic skin (round the mouth, cheeks, brows and forehead,
#: :func:`~scan2morph.modal.skin.mimic_skin`) than on the nose, the jaw's sides and the chin;
#: its outline clamped where every expression leaves it still (``fixed_outline: every_still``)
#: and elsewhere held by the skin beyond the cut, a strip 6 mm wide under the same tension
#: (``outline_strip_mm``: a Robin edge, :func:`~scan2morph.modal.skin.edge_springs`); its
#: coordinates are the least squares fit (``coordinates: vertex``). ``skin_v1``: the skin as
#: first adopted, the clamp and the tether chosen from every take (visemes too), the outline
#: clamped where the median take leaves it still and free elsewhere. Chosen by
#: ``benchmarks/bench_modal_span.py`` (docs/outputs.md, "The modal basis's physics").
PRESETS: dict[str, dict] = {
    "paper": {
        "fixed_outline": "all",
        "thickness_mm": 1.0,
        "youngs_modulus_mpa": 210000.0,
        "poisson_ratio": 0.3,
        "density_t_per_mm3": 7.85e-9,
        "stiff_above": "nose_tip",
        "stiff_factor": 3.0,
        "membrane_scale": 1.0,
        "rotary_inertia": True,
        "mass": "consistent",
        "tension_n_per_mm": 0.0,
        "foundation_n_per_mm3": 0.0,
        "tether_n_per_mm3": 0.0,
        "tether_normal_n_per_mm3": 0.0,
        "tether_region": "none",
        "mimic_tension_factor": 1.0,
        "mimic_foundation_factor": 1.0,
        "mimic_mass_factor": 1.0,
        "coordinates": "mass",
        "still_from": "takes",
        "outline_strip_mm": 0.0,
    },
}
PRESETS["clamped_still"] = PRESETS["paper"] | {"fixed_outline": "still"}
PRESETS["skin"] = PRESETS["paper"] | {
    "fixed_outline": "every_still",
    "youngs_modulus_mpa": 0.0,
    "density_t_per_mm3": 1.1e-9,
    "stiff_factor": 1.0,
    "rotary_inertia": False,
    "tension_n_per_mm": 1.0,
    "foundation_n_per_mm3": 0.01,
    "tether_n_per_mm3": 0.1,
    "tether_normal_n_per_mm3": 0.1,
    "tether_region": "still",
    "mimic_mass_factor": 1.4,
    "coordinates": "vertex",
    "still_from": "expressions",
    "outline_strip_mm": 6.0,
}
PRESETS["skin_v1"] = PRESETS["skin"] | {
    "fixed_outline": "still",
    "still_from": "takes",
    "outline_strip_mm": 0.0,
}
#: The preset used when the config names none.
DEFAULT_PRESET = "skin"
#: Outline policies: clamp the whole outline, the part the median take leaves still, the part
#: every take leaves still, or nothing (a free model).
FIXED_OUTLINE = POLICIES
TETHER_REGIONS = ("still", "stable", "none")
#: Whose stillness chooses the clamped outline and the tethered skin: the expressions' (when the
#: subject has any; the modes are there to rebuild them), or every take's (visemes too).
STILL_FROM = ("expressions", "takes")


def physics(modal: Mapping, source: str = "config modal") -> dict:
    """The preset's physics with the section's own values of the same keys over it.

    Parameters
    ----------
    modal : mapping
        The config section ``modal`` (``preset`` and any overrides; a None value keeps the
        preset's).
    source : str
        Label for error messages.

    Returns
    -------
    dict
        One value per key of :data:`PRESETS`, plus ``preset``.
    """
    name = modal.get("preset") or DEFAULT_PRESET
    if name not in PRESETS:
        raise InputError(source, f"preset: expected one of {sorted(PRESETS)}, got {name!r}")
    out = dict(PRESETS[name])
    out.update({k: modal[k] for k in out if modal.get(k) is not None})
    if out["fixed_outline"] not in FIXED_OUTLINE:
        raise InputError(
            source, f"fixed_outline: expected one of {FIXED_OUTLINE}, got {out['fixed_outline']!r}"
        )
    if out["tether_region"] not in TETHER_REGIONS:
        raise InputError(
            source, f"tether_region: expected one of {TETHER_REGIONS}, got {out['tether_region']!r}"
        )
    if out["still_from"] not in STILL_FROM:
        raise InputError(
            source, f"still_from: expected one of {STILL_FROM}, got {out['still_from']!r}"
        )
    strip = out["outline_strip_mm"]
    if isinstance(strip, bool) or not isinstance(strip, int | float) or not 0 <= strip < np.inf:
        raise InputError(source, f"outline_strip_mm: expected a number >= 0 (mm), got {strip!r}")
    heavier = float(out["mimic_mass_factor"]) != 1.0
    if heavier and (float(out["youngs_modulus_mpa"]) != 0.0 or out["mass"] == "vertex"):
        raise InputError(
            source,
            f"mimic_mass_factor: {out['mimic_mass_factor']} weighs a membrane's mass per area, so it "
            "needs youngs_modulus_mpa 0 and mass consistent or lumped (preset "
            f"{name!r} gives youngs_modulus_mpa {out['youngs_modulus_mpa']}, mass "
            f"{out['mass']!r}); set it to 1 or use the skin preset",
        )
    return {"preset": name} | out


@dataclass(frozen=True)
class Params:
    """Modal parameters.

    Attributes
    ----------
    levels : int
        Template subdivisions.
    modal : ModalParams
        Modes, shell thickness (mm), stiffening, material, skin terms, threads, seed.
    stiff_above : str
        Named point above which the face is stiffened (``modal.stiff_above``).
    semantic_labels : list of str
        Expression labels whose first take becomes a semantic mode.
    reconstruction_k : list of int
        Numbers of modes at which the reconstruction error is reported.
    fixed_outline : {"still", "every_still", "all", "none"}
        Outline vertices clamped: those the median take does not move (``still``), those no
        take moves (``every_still``), all (the paper) or none (a free model); the takes are
        those of ``still_from``.
    still_mm : float
        Median displacement over the takes below which an outline vertex is still
        (``fixed_outline: still``), and the longest displacement below which a vertex is still
        (``tether_region: still``), mm.
    min_fixed_share : float
        Share of the outline clamped at least.
    target_rms_mm : float
        Reconstruction error whose mode count is reported, mm.
    tether_region : {"still", "stable", "none"}
        Vertices whose skin is tied to the bone: those the takes (of ``still_from``) leave
        still (within ``still_mm``), the template's stable face, or none.
    still_from : {"expressions", "takes"}
        Whose stillness chooses the clamped outline and the tethered skin: the expressions'
        (when the subject has any, else every take's), or every take's.
    physics : dict
        The resolved physics (:func:`physics`: the preset's name and every value), recorded
        in the store.
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
    tether_region: str = "none"
    physics: dict = field(default_factory=dict)
    still_from: str = "takes"

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``modal`` and ``template`` (one thread: see
        :meth:`with_threads`); the physics is the preset's (``modal.preset``) with the section's
        overrides."""
        modal, template = config["modal"], config["template"]
        phys = physics(modal)
        params = ModalParams(
            n_modes=modal["modes"],
            thickness_mm=float(phys["thickness_mm"]),
            upper_thickness_factor=float(phys["stiff_factor"]),
            material=ShellMaterial(
                float(phys["youngs_modulus_mpa"]),
                float(phys["poisson_ratio"]),
                float(phys["density_t_per_mm3"]),
                float(phys["membrane_scale"]),
                bool(phys["rotary_inertia"]),
            ),
            threads=1,
            seed=modal["seed"],
            mass=str(phys["mass"]),
            tension_n_per_mm=float(phys["tension_n_per_mm"]),
            foundation_n_per_mm3=float(phys["foundation_n_per_mm3"]),
            tether_n_per_mm3=float(phys["tether_n_per_mm3"]),
            tether_normal_n_per_mm3=float(phys["tether_normal_n_per_mm3"]),
            mimic_tension_factor=float(phys["mimic_tension_factor"]),
            mimic_foundation_factor=float(phys["mimic_foundation_factor"]),
            mimic_mass_factor=float(phys["mimic_mass_factor"]),
            clamp_strip_mm=float(phys["outline_strip_mm"]),
            coordinates=str(phys["coordinates"]),
        )
        return cls(
            int(template["subdivision_levels"]),
            params,
            str(phys["stiff_above"]),
            list(modal["semantic_labels"]),
            list(modal["reconstruction_k"]),
            str(phys["fixed_outline"]),
            float(modal.get("still_mm", 1.0)),
            float(modal.get("min_fixed_share", 0.25)),
            float(modal.get("target_rms_mm", 0.5)),
            str(phys["tether_region"]),
            phys,
            str(phys["still_from"]),
        )

    def with_threads(self, threads: int) -> Params:
        """The same parameters, with the eigensolver's threads (the job's)."""
        return replace(self, modal=replace(self.modal, threads=threads))


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
    template's outer loop, from the fields of :func:`still_fields`).

    The paper fixes the face's outline; the mouth loop (the lips) stays free. With
    ``fixed_outline: still`` (``every_still``), only the part of the outline that the median
    take (every take) does not move.
    """
    return still_outline(
        fine.boundary,
        still_fields(subject, data, fields, params),
        fine.n_vertices,
        params.fixed_outline,
        params.still_mm,
        params.min_fixed_share,
        source=subject.name,
    )


def natural_basis(
    fine: Template,
    subject: Subject,
    data: Mapping[str, np.ndarray],
    fields: Mapping[str, np.ndarray],
    params: Params,
) -> tuple[ModalBasis, OutlineChoice]:
    """The subject's natural basis with the configured physics (what :func:`run` stores).

    Parameters
    ----------
    fine : Template
        The subdivided template.
    subject, data, fields, params
        As in :func:`outline_choice`.

    Returns
    -------
    basis : ModalBasis
    outline : OutlineChoice
        The outline and its clamped part.
    """
    from scan2morph.modal import modal_basis

    outline = outline_choice(fine, subject, data, fields, params)
    basis = modal_basis(
        need(data, paths.neutral("vertices"), subject.name),
        fine.faces,
        params.modal,
        upper_face(fine, params.stiff_above),
        fixed=held(outline, params),
        tethered=tethered(fine, params, still_fields(subject, data, fields, params)),
        mimic=mimic(fine, params),
        source=subject.name,
    )
    return basis, outline


def held(outline: OutlineChoice, params: Params) -> Held:
    """The clamped outline, and the rest of the outline held by the skin beyond the cut when
    the physics has a strip (``outline_strip_mm`` > 0; else it is free)."""
    free = outline.outline & ~outline.fixed
    return Held(outline.fixed, free if params.modal.clamp_strip_mm else np.zeros_like(free))


def mimic(fine: Template, params: Params) -> np.ndarray | None:
    """The template's mimic skin (:func:`~scan2morph.modal.skin.mimic_skin`) when a
    ``modal.mimic_*_factor`` is not 1, else None."""
    from scan2morph.modal import mimic_skin

    m = params.modal
    factors = (m.mimic_tension_factor, m.mimic_foundation_factor, m.mimic_mass_factor)
    return mimic_skin(fine) if any(x != 1.0 for x in factors) else None


def takes_motion(
    subject: Subject, data: Mapping[str, np.ndarray], fields: Mapping[str, np.ndarray]
) -> list[np.ndarray]:
    """The visemes' motion and the expressions' displacement ``fields``, (V, 3) mm each."""
    moved = [
        data[paths.viseme(t, "motion")]
        for t in subject.visemes
        if paths.viseme(t, "motion") in data
    ]
    return [*moved, *fields.values()]


def still_fields(
    subject: Subject,
    data: Mapping[str, np.ndarray],
    fields: Mapping[str, np.ndarray],
    params: Params,
) -> list[np.ndarray]:
    """The fields whose stillness chooses the clamped outline and the tethered skin: the
    expressions' displacement ``fields`` (``still_from: expressions``, when there are any),
    else every take's (:func:`takes_motion`)."""
    if params.still_from == "expressions" and fields:
        return list(fields.values())
    return takes_motion(subject, data, fields)


def tethered(fine: Template, params: Params, moved: list | None = None) -> np.ndarray | None:
    """Vertices whose skin is tied to the bone (``modal.tether_region``), or None.

    ``still``: the vertices every take in ``moved`` (:func:`still_fields`) leaves within
    ``modal.still_mm`` (:func:`~scan2morph.modal.boundary.still_skin`), the template's stable
    face when there are no takes; ``stable``: the template's stable face.
    """
    if params.tether_region == "still" and moved:
        return still_skin(moved, fine.n_vertices, params.still_mm)
    return stable_face(fine) if params.tether_region in ("still", "stable") else None


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
        stay still) and, for textured expression meshes, the neutral's fit part (``mesh/uv``)
        and repair part (``range/color``), as the morph stage reads them (the subject job gives
        them; without them the meshes are written without a texture).
    params : Params

    Returns
    -------
    Part
        ``/modal/*`` (with ``/modal/preset`` and ``/modal/physics``, the resolved physics as
        JSON) and ``/expressions/{take}/coordinates|reconstruction_rms_mm|
        reconstruction_normal_rms_mm|reconstruction_tangential_rms_mm|modes_to_target|
        outline_rms_mm|clamped_rms_mm|synthesized|semantic_coordinates``; ``files``: the
        ``coordinates`` and ``reconstruction`` tables, and the measured and synthesised
        expression ``meshes`` with their ``faces`` and the neutral's ``uv`` and ``texture``
        (None when ``data`` has not got them).
    """
    subject = modelled(subject, data)
    fine = subdivide_template(template, params.levels)
    name = subject.name
    base = need(data, paths.neutral("vertices"), name)
    fields = {t: need(data, paths.expression(t, "displacement"), name) for t in subject.expressions}
    natural, outline = natural_basis(fine, subject, data, fields, params)
    log.info(
        "%s: preset %s, %d of %d outline vertices clamped (fixed_outline: %s), %d held by the "
        "skin beyond the outline (outline_strip_mm: %g)",
        name,
        params.physics.get("preset", "?"),
        int(outline.fixed.sum()),
        int(outline.outline.sum()),
        params.fixed_outline,
        int(held(outline, params).sprung.sum()),
        params.modal.clamp_strip_mm,
    )
    shell = NeutralShell(base, fine.faces, upper_face(fine, params.stiff_above))
    expressions = ExpressionFields(
        fields,
        subject.labels,
        semantic_takes(subject, params.semantic_labels),
        params.reconstruction_k,
        params.target_rms_mm,
    )
    basis, datasets = subject_modal(
        shell, params.modal, expressions, name, fixed=outline, basis=natural
    )
    datasets[paths.modal("preset")] = str(params.physics.get("preset", ""))
    datasets[paths.modal("physics")] = json.dumps(params.physics, sort_keys=True)
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
        ).astype({"modes_to_target": "Int64"}),  # a count (NA where no K reaches the target)
        "faces": fine.faces,
        "meshes": meshes,
        # the neutral's skin, as the models wear it (stages.morph): vertex i is the same
        # template vertex in every expression mesh
        "uv": data.get(paths.mesh(subject.neutral, "uv")),
        "texture": data.get(paths.range_image(subject.neutral, "color")),
    }
    attrs = {} if takes else {paths.SKIPPED: {"modal_coordinates": NO_EXPRESSIONS}}
    return Part(datasets, attrs=attrs, files=files)


def write_files(part: Part, coordinates: str, reconstruction: str, meshes: str) -> None:
    """Write the coordinate and reconstruction tables (TSV with their column dictionaries, one
    row per expression take) and the measured and synthesised expression meshes (OBJ) into the
    folder ``meshes``, textured with the neutral's texture when the part has it (one material
    the folder's meshes share, as the models')."""
    from scan2morph.tables import MODAL_COORDINATES, MODAL_RECONSTRUCTION, write_table

    f = part.files
    coords = f["coordinates"].rename_axis("take").reset_index()
    write_table(coordinates, coords, MODAL_COORDINATES)
    write_table(reconstruction, f["reconstruction"], MODAL_RECONSTRUCTION, float_format="%.4f")
    folder = Path(meshes)
    folder.mkdir(parents=True, exist_ok=True)
    skin = None
    if f["texture"] is not None and f["meshes"]:
        skin = write_material(folder, NEUTRAL_MATERIAL, f["texture"])
    uv = f["uv"] if skin else None
    for name, vertices in f["meshes"].items():
        write_obj(folder / f"{name}.obj", vertices, f["faces"], uv=uv, texture=skin)
