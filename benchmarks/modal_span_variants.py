"""The basis configurations of ``bench_modal_span.py`` (:data:`VARIANTS`) and how the bench
builds those the stage cannot (:data:`BENCH_KEYS`: a strip on part of the outline, heavier
brows): their physics and why each was tried are in that benchmark's docstring."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

#: Basis configurations: a preset and the config keys set over it. The presets are the
#: candidates for the default; the variants are the other physics measured on the way.
VARIANTS: dict[str, dict] = {
    "paper": {"preset": "paper"},
    "clamped_still": {"preset": "clamped_still"},
    "skin": {"preset": "skin"},
    "skin_v1": {"preset": "skin_v1"},
    # the variants below were measured on the first skin preset (skin_v1)
    "free_steel": {"preset": "paper", "fixed_outline": "none"},
    "free_thick_soft_membrane": {
        "preset": "paper",
        "fixed_outline": "none",
        "thickness_mm": 10.0,
        "stiff_factor": 1.0,
        "membrane_scale": 0.1,
        "rotary_inertia": False,
    },
    "skin_tension_only": {
        "preset": "skin_v1",
        "foundation_n_per_mm3": 0.0,
        "tether_n_per_mm3": 0.0,
        "tether_normal_n_per_mm3": 0.0,
    },
    "skin_no_tether": {
        "preset": "skin_v1",
        "tether_n_per_mm3": 0.0,
        "tether_normal_n_per_mm3": 0.0,
    },
    "skin_tangential_tether": {"preset": "skin_v1", "tether_normal_n_per_mm3": 0.0},
    "skin_free_outline": {"preset": "skin_v1", "fixed_outline": "none"},
    # (the shells and a vertex's mass have no membrane mass per area for the mimic skin to weigh:
    # its factor is 1 in these three, as when they were first measured, before the skin preset had it)
    "skin_stiff_upper": {
        "preset": "skin_v1",
        "stiff_factor": 3.0,
        "youngs_modulus_mpa": 1.0,
        "mimic_mass_factor": 1.0,
    },
    "skin_vertex_mass": {"preset": "skin_v1", "mass": "vertex", "mimic_mass_factor": 1.0},
    "skin_stable_tether": {  # the skin preset as first measured: a light tie on the stable face
        "preset": "skin_v1",
        "foundation_n_per_mm3": 0.005,
        "tether_n_per_mm3": 0.003,
        "tether_normal_n_per_mm3": 0.01,
        "tether_region": "stable",
        "coordinates": "mass",
        "fixed_outline": "none",
    },
    # skin until the membrane
    "skin_soft_shell": {"preset": "skin_v1", "youngs_modulus_mpa": 0.01, "mimic_mass_factor": 1.0},
    "skin_still_no_foundation": {"preset": "skin_v1", "foundation_n_per_mm3": 0.0},
    "skin_still_tension_0.5": {"preset": "skin_v1", "tension_n_per_mm": 0.5},
    # The skin varying over the face (the mimic skin of scan2morph.modal.skin), measured with
    # brows1 and frown1 in the cohort against skin before it (uniform): the share left of the
    # worst expression moves by -0.14 (synth01 frown1, K = 25) to +0.08 at K = 25 / 50 / 100,
    # with the mimic lines round the mouth, cheeks and brows only: heavier mimic skin (mass
    # 2, 4) helps the smiles and sad faces at K = 50 (synth04 sad1 0.46 -> 0.39) and hurts the
    # brow expressions (synth02 brows1 +0.08); softer (tension 0.5) is worse at K = 25 (up to
    # +0.16); a softer foundation there (0.3) helps the brow expressions and the real smile's
    # normal part and costs sad faces up to +0.02. With the forehead (frontalis) in the mimic
    # skin too, mass 1.2-1.4 moves no expression by more than +0.004 and takes synth01 at
    # K = 50 from 0.40 to 0.34 (the skin preset's mimic_mass_factor).
    "skin_uniform": {"preset": "skin_v1", "mimic_mass_factor": 1.0},
    "skin_mimic_mass_2": {"preset": "skin_v1", "mimic_mass_factor": 2.0},
    "skin_mimic_mass_4": {"preset": "skin_v1", "mimic_mass_factor": 4.0},
    "skin_mimic_tension_0.5": {"preset": "skin_v1", "mimic_tension_factor": 0.5},
    "skin_mimic_foundation_0.3": {"preset": "skin_v1", "mimic_foundation_factor": 0.3},
    "skin_mimic_mass_1.5_foundation_0.5": {
        "preset": "skin_v1",
        "mimic_mass_factor": 1.5,
        "mimic_foundation_factor": 0.5,
    },
    # over the skin preset's mimic mass 1.4: neither leaves less on every expression (softer:
    # synth01 frown1 +0.15 at K = 25; the foundation: synth03 frown1 +0.04 at K = 25)
    "skin_mimic_tension_0.8": {"preset": "skin_v1", "mimic_tension_factor": 0.8},
    "skin_mimic_foundation_0.8": {"preset": "skin_v1", "mimic_foundation_factor": 0.8},
    "skin_still_0.5": {"preset": "skin_v1", "still_mm": 0.5},  # tied and clamped: less skin
    "skin_still_2": {"preset": "skin_v1", "still_mm": 2.0},  # more skin
    "skin_foundation_0.003": {"preset": "skin_v1", "foundation_n_per_mm3": 0.003},
    "skin_foundation_0.03": {"preset": "skin_v1", "foundation_n_per_mm3": 0.03},
    # the clamp replaced by the skin beyond the cut, a strip l mm wide held at its far edge
    # (ModalParams.clamp_strip_mm, a library parameter, no config key; see bench_modal_span.py's docstring)
    "skin_strip_3": {"preset": "skin_v1", "clamp_strip_mm": 3.0},
    "skin_strip_10": {"preset": "skin_v1", "clamp_strip_mm": 10.0},
    # the strip only where the smiles move the outline, or the brows heavier beside it (issue
    # #37; bench keys, BENCH_KEYS): none is within +0.005 of skin everywhere (bench_modal_span.py)
    "skin_strip_3_below_eyes": {
        "preset": "skin_v1",
        "clamp_strip_mm": 3.0,
        "strip_below": "eye_r_outer",
    },
    "skin_strip_3_below_nose": {
        "preset": "skin_v1",
        "clamp_strip_mm": 3.0,
        "strip_below": "nose_tip",
    },
    "skin_strip_10_below_nose": {
        "preset": "skin_v1",
        "clamp_strip_mm": 10.0,
        "strip_below": "nose_tip",
    },
    "skin_strip_3_brow_2": {"preset": "skin_v1", "clamp_strip_mm": 3.0, "brow_mass_factor": 2.0},
    "skin_brow_2": {"preset": "skin_v1", "brow_mass_factor": 2.0},
    "skin_strip_1_brow_1.6": {"preset": "skin_v1", "clamp_strip_mm": 1.0, "brow_mass_factor": 1.6},
    "skin_strip_0.5_brow_1.6": {
        "preset": "skin_v1",
        "clamp_strip_mm": 0.5,
        "brow_mass_factor": 1.6,
    },
    "skin_strip_3_mimic_1.6": {
        "preset": "skin_v1",
        "clamp_strip_mm": 3.0,
        "mimic_mass_factor": 1.6,
    },
    "skin_strip_1_mimic_1.6": {
        "preset": "skin_v1",
        "clamp_strip_mm": 1.0,
        "mimic_mass_factor": 1.6,
    },
    "skin_strip_3_mimic_1.6_brow_1.6": {
        "preset": "skin_v1",
        "clamp_strip_mm": 3.0,
        "mimic_mass_factor": 1.6,
        "brow_mass_factor": 1.6,
    },
}


def variant_params(cfg: dict, variant: dict):
    """The modal stage's parameters for a configuration (its ``clamp_strip_mm`` set on the
    :class:`~scan2morph.modal.ModalParams`: no config key), two eigensolver threads."""
    from dataclasses import replace

    from scan2morph.stages import modal

    keys = {k: x for k, x in variant.items() if k not in BENCH_KEYS}
    strip = keys.pop("clamp_strip_mm", None)
    params = modal.Params.from_config(cfg | {"modal": dict(cfg["modal"]) | keys}).with_threads(2)
    if strip is None:  # the preset's outline_strip_mm
        return params
    return replace(params, modal=replace(params.modal, clamp_strip_mm=float(strip)))


#: Variant keys the bench applies itself (no config key, no stage parameter): ``strip_below``,
#: a named template point below which (canonical y down) the outline is held by the strip of
#: ``clamp_strip_mm`` and above which it stays clamped; ``brow_mass_factor``, a factor on the
#: membrane's mass per area along the brows (:data:`BROW_LINES`) on top of the mimic skin's.
BENCH_KEYS = ("strip_below", "brow_mass_factor")
#: The brows over the glabella, as in :data:`scan2morph.modal.skin.MIMIC_LINES`.
BROW_LINES = ((("brow_r_outer", "brow_r_inner", "brow_l_inner", "brow_l_outer"), 0.3),)


def mass_weight(params, mimic_w, brow_w, brow_factor: float):
    """The mimic weight and mass factor that give the membrane's mass per area
    ``1 + (m - 1) mimic_w + (b - 1) brow_w`` (``m`` the preset's mimic mass factor, ``b`` the
    brows'): factor ``m + b - 1``, weight the excess over 1 divided by ``m + b - 2``; the params
    with that factor (tension and foundation factors must be 1)."""
    from dataclasses import replace

    m = params.modal
    assert (m.mimic_tension_factor, m.mimic_foundation_factor) == (1.0, 1.0)
    top = m.mimic_mass_factor + brow_factor - 1.0
    w = ((m.mimic_mass_factor - 1.0) * mimic_w + (brow_factor - 1.0) * brow_w) / (top - 1.0)
    return np.clip(w, 0.0, 1.0), replace(params, modal=replace(m, mimic_mass_factor=top))


@contextmanager
def strip_only(mask):
    """Within it, :func:`scan2morph.modal.modal_basis`'s strip (``clamp_strip_mm``) holds only
    the fixed boundary vertices of ``mask`` ((V,) bool, None: all); the other fixed vertices
    stay clamped (a bench-only variant: the library's strip holds every fixed boundary
    vertex)."""
    from scan2morph.modal import basis as lib

    original = lib._strip

    def partial(v, f, fixed, k_mat, p, source, sprung=None):
        k_out, kept = original(v, f, fixed & mask, k_mat, p, source, sprung)
        return k_out, kept | (fixed & ~mask)

    if mask is not None:
        lib._strip = partial
    try:
        yield
    finally:
        lib._strip = original


def custom_basis(case: dict, params, variant: dict):
    """The natural basis as :func:`scan2morph.stages.modal.natural_basis` makes it, with the
    bench's own keys (:data:`BENCH_KEYS`) applied."""
    from scan2morph.modal import mimic_skin, modal_basis
    from scan2morph.modal.skin import mimic_weight
    from scan2morph.stages import modal
    from scan2morph.store import paths
    from scan2morph.template.regions import upper_face

    fine, subj, data, fields = case["fine"], case["subject"], case["data"], case["fields"]
    outline = modal.outline_choice(fine, subj, data, fields, params)
    xy = np.asarray(fine.vertices, dtype=np.float64)[:, :2]
    strip = None
    if variant.get("strip_below"):
        strip = xy[:, 1] > xy[fine.named[variant["strip_below"]], 1]
    weight = modal.mimic(fine, params)
    if variant.get("brow_mass_factor", 1.0) != 1.0:
        lines = [(xy[[fine.named[n] for n in names]], w) for names, w in BROW_LINES]
        brow = mimic_weight(xy, lines, "template")
        weight, params = mass_weight(params, mimic_skin(fine), brow, variant["brow_mass_factor"])
    with strip_only(strip):
        basis = modal_basis(
            data[paths.neutral("vertices")],
            fine.faces,
            params.modal,
            upper_face(fine, params.stiff_above),
            fixed=modal.held(outline, params),
            tethered=modal.tethered(fine, params, modal.still_fields(subj, data, fields, params)),
            mimic=weight,
            source=subj.name,
        )
    return basis, outline
