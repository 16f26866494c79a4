"""Tests of what the modal bases span (scan2morph.modal.span), the skin physics and the presets.

Analytic oracles: the Neumann spectrum of a rectangle (Laplace-Beltrami anchor); the modes of a
flat square membrane under isotropic tension with a free edge, in plane and out of plane, with and
without a foundation under it (the ``skin`` physics); a simply supported steel plate whose first
mode is the bending mode sin(pi x / a) sin(pi y / a) (the ``paper`` physics spans it and not the
same shape in plane); a square membrane whose edge the skin beyond the cut holds (a Robin edge:
the wavenumbers of a string with spring-held ends), wholly or on one side with the others
clamped. Least squares against numpy's.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals
from scan2morph.modal import Held, ModalParams, ShellMaterial, modal_basis, project, reconstruct
from scan2morph.modal.basis import vertex_orthonormal
from scan2morph.modal.fem import (
    assemble,
    boundary_vertices,
    face_areas,
    membrane_mass,
)
from scan2morph.modal.skin import cotangent_laplacian, skin_stiffness
from scan2morph.modal.span import (
    laplace_beltrami,
    per_axis_fields,
    residual_split,
    span_curve,
)
from scan2morph.stages import Subject, modal
from scan2morph.store import paths
from tests.support.meshes import plate_mesh

A_MM, T_N_PER_MM, RHO, H_MM = 100.0, 1.0, 1.1e-9, 1.0


def membrane_params(n_modes: int, foundation: float = 0.0) -> ModalParams:
    """A skin under tension on a negligible shell (E 1e-4 MPa: its membrane stiffness is
    1e-4 of the tension, its bending far less), rotations without inertia."""
    return ModalParams(
        n_modes=n_modes,
        thickness_mm=H_MM,
        upper_thickness_factor=1.0,
        material=ShellMaterial(1e-4, 0.3, RHO, rotary_inertia=False),
        tension_n_per_mm=T_N_PER_MM,
        foundation_n_per_mm3=foundation,
        method="block",
    )


def membrane_hz(m: int, n: int, foundation: float = 0.0) -> float:
    """Free square membrane, mode cos(m pi x / a) cos(n pi y / a): omega^2 rho h = T k^2 (+ k_n
    for motion along the normal)."""
    k2 = (np.pi / A_MM) ** 2 * (m * m + n * n)
    return float(np.sqrt((T_N_PER_MM * k2 + foundation) / (RHO * H_MM)) / (2 * np.pi))


@pytest.fixture(scope="module")
def plate():
    return plate_mesh(16)


@pytest.fixture(scope="module")
def coarse_plate():
    """A 10 x 10 plate, for what holds on any mesh (least squares, limits): a tenth of the
    16 x 16 plate's dense eigensolves."""
    return plate_mesh(10)


@pytest.fixture(scope="module")
def skin_plate(plate):
    v, f = plate
    free = np.zeros(len(v), bool)
    return modal_basis(v, f, membrane_params(18), fixed=free, source="membrane")


def test_cotangent_laplacian_integrates_a_linear_gradient(plate):
    v, f = plate
    lap, area = cotangent_laplacian(v, f)
    assert_allclose(area.sum(), A_MM * A_MM, rtol=1e-12)
    assert_allclose(lap @ np.ones(len(v)), 0.0, atol=1e-9)
    g = 0.3 * v[:, 0] - 0.2 * v[:, 1]  # |grad g|^2 = 0.13 everywhere
    assert_allclose(g @ (lap @ g), 0.13 * A_MM * A_MM, rtol=1e-9)


def test_laplace_beltrami_matches_the_neumann_spectrum_of_a_rectangle():
    v, f = plate_mesh(24)
    v = v * [1.0, 0.6, 1.0]  # 100 x 60 mm
    lam, phi = laplace_beltrami(v, f, 6)
    exact = sorted(
        (np.pi * m / 100.0) ** 2 + (np.pi * n / 60.0) ** 2 for m in range(4) for n in range(3)
    )
    assert abs(lam[0]) < 1e-9
    assert_allclose(lam[1:], exact[1:6], rtol=0.02)
    _, area = cotangent_laplacian(v, f)
    assert_allclose(phi.T @ (area[:, None] * phi), np.eye(6), atol=1e-8)
    fields = per_axis_fields(phi)
    assert fields.shape == (18, len(v), 3)
    assert_allclose(fields[3 * 2 + 1, :, 1], phi[:, 2]) and not fields[3 * 2 + 1, :, [0, 2]].any()


def test_span_curve_is_least_squares_with_dependent_fields():
    rng = np.random.default_rng(4)
    n_v, k = 40, 9
    basis = rng.normal(size=(k, n_v, 3))
    basis[3] = 0.0  # adds nothing
    basis[6] = 2.0 * basis[1] - basis[2]  # dependent on earlier ones
    field = rng.normal(size=(n_v, 3))
    normals = rng.normal(size=(n_v, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    where = rng.random(n_v) > 0.2
    outline = rng.random(n_v) > 0.7
    c = span_curve(basis, field, range(k + 1), normals, where, outline)
    for kk in range(k + 1):
        a = basis[:kk, where].reshape(kk, 3 * where.sum()).T
        b = field[where].ravel()
        fit = np.linalg.lstsq(a, b, rcond=None)[0]
        e = np.zeros_like(field)
        e[where] = (b - a @ fit).reshape(-1, 3)
        assert_allclose(
            [c.total_mm[kk], c.normal_mm[kk], c.tangential_mm[kk], c.inner_mm[kk]],
            residual_split(e, normals, where, outline),
            rtol=1e-9,
        )
    assert_allclose(c.total_mm**2, c.normal_mm**2 + c.tangential_mm**2, rtol=1e-9)
    assert c.total_mm[0] == c.field_mm and c.left[0] == 1.0
    with pytest.raises(InputError, match="ks"):
        span_curve(basis, field, [k + 1], normals)
    with pytest.raises(InputError, match="expected basis"):
        span_curve(basis[:, :5], field, [1], normals)


def test_skin_membrane_modes_match_membrane_theory(skin_plate):
    """In plane and out of plane alike: three rigid translations, then the (1, 0) and (0, 1)
    modes along x, y and z (six at one frequency), then (1, 1) three times, (2, 0), (0, 2)."""
    freqs = skin_plate.frequencies_hz
    assert np.all(freqs[:3] < 1e-3 * freqs[3])
    exact = np.repeat([membrane_hz(1, 0), membrane_hz(1, 1), membrane_hz(2, 0)], [6, 3, 6])
    assert_allclose(freqs[3:18], exact, rtol=0.02)


def test_a_membrane_without_shell_matches_membrane_theory(plate, skin_plate):
    """E = 0: no shell, the tension alone on the translations. The same frequencies as the
    membrane theory and as the skin on a negligible shell, and no rotation in any vector."""
    v, f = plate
    params = replace(membrane_params(18), material=ShellMaterial(0.0, 0.3, RHO))
    basis = modal_basis(v, f, params, fixed=np.zeros(len(v), bool), source="membrane")
    freqs = basis.frequencies_hz
    assert np.all(freqs[:3] < 1e-3 * freqs[3])
    exact = np.repeat([membrane_hz(1, 0), membrane_hz(1, 1), membrane_hz(2, 0)], [6, 3, 6])
    assert_allclose(freqs[3:18], exact, rtol=0.02)
    assert_allclose(freqs[3:], skin_plate.frequencies_hz[3:], rtol=1e-3)
    assert np.all(basis.dof_modes[:, :, 3:] == 0)
    # no tension, foundation or tether: nothing holds the membrane
    bare = replace(params, tension_n_per_mm=0.0)
    with pytest.raises(InputError, match="youngs_modulus_mpa: 0"):
        modal_basis(v, f, bare, fixed=np.zeros(len(v), bool))


@pytest.mark.parametrize("kind", ["consistent", "lumped", "vertex"])
def test_membrane_mass_is_the_shells_translational_mass(plate, kind):
    """Oracle: pyfe3d's shell mass without rotary inertia (consistent), and for every kind
    the total rho t A on each axis, none on the rotations."""
    v, f = plate
    t = np.where(np.arange(len(f)) % 3 == 0, 2.0, 1.0)
    m = membrane_mass(v, f, t, RHO, kind)
    total = RHO * np.sum(t * face_areas(v, f))
    for axis in range(6):
        want = total if axis < 3 else 0.0
        assert_allclose(m[axis::6, axis::6].sum(), want, rtol=1e-12)
    if kind == "consistent":
        _, shell = assemble(v, f, t, ShellMaterial(1.0, 0.3, RHO, rotary_inertia=False))
        assert abs(m - shell).max() < 1e-12 * abs(shell).max()
    with pytest.raises(InputError, match="density"):
        membrane_mass(v, f, t, 0.0, kind)


@pytest.mark.parametrize("on_bone", [False, True])
def test_a_foundation_lifts_only_the_normal_modes(plate, on_bone):
    """k_n under the skin: omega^2 rho h = T k^2 + k_n for motion along the plate's normal (z);
    the in-plane modes keep their frequencies. On bone (tethered vertices, no tangential tie)
    half of it given as the bone's normal stiffness lifts them alike."""
    v, f = plate
    kn = T_N_PER_MM * (np.pi / A_MM) ** 2 * 3.0  # between the (1,1) and (2,0) in-plane modes
    params = membrane_params(14, kn)
    tethered = None
    if on_bone:
        params = ModalParams(
            **(vars(params) | {"foundation_n_per_mm3": kn / 2, "tether_normal_n_per_mm3": kn / 2})
        )
        tethered = np.ones(len(v), bool)
    basis = modal_basis(v, f, params, fixed=np.zeros(len(v), bool), tethered=tethered)
    modes = basis.modes
    along_z = np.sum(modes[:, :, 2] ** 2, axis=1) / np.sum(modes**2, axis=(1, 2))
    normal, plane = basis.frequencies_hz[along_z > 0.99], basis.frequencies_hz[along_z < 0.01]
    assert len(normal) + len(plane) == 14
    assert_allclose(normal[:3], [membrane_hz(0, 0, kn)] + [membrane_hz(1, 0, kn)] * 2, rtol=0.02)
    in_plane = [0.0, 0.0] + [membrane_hz(1, 0)] * 4 + [membrane_hz(1, 1)] * 2
    assert_allclose(plane[2:8], in_plane[2:8], rtol=0.02) and np.all(plane[:2] < 1e-2 * plane[2])


def test_skin_spans_in_plane_and_normal_shapes_analytically(plate, skin_plate):
    """cos(pi x / a) along z plus cos(pi y / a) along x lies in the span of the first 9 skin
    modes (translations and the six (1,0)/(0,1) modes) and of none of the first 3; the stored
    coordinates (rotations without inertia: q = Q^T M v is mass-weighted least squares) rebuild
    it as well."""
    v, f = plate
    field = np.zeros((len(v), 3))
    field[:, 2] = 2.0 * np.cos(np.pi * v[:, 0] / A_MM)
    field[:, 0] = 1.5 * np.cos(np.pi * v[:, 1] / A_MM)
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    rim = boundary_vertices(f, len(v))
    c = span_curve(skin_plate.modes, field, [3, 9], normals, outline=rim)
    assert c.left[0] > 0.99 and c.left[1] < 0.02
    stored = field - reconstruct(skin_plate, project(skin_plate, field), 9)
    assert residual_split(stored, normals, np.ones(len(v), bool), rim)[0] < 0.02 * c.field_mm


def test_steel_plate_bends_first_and_slides_last(plate):
    """The paper's physics on a simply supported steel plate: its first mode is the bending
    shape sin(pi x / a) sin(pi y / a) along z (spanned at K = 1); the same shape in plane is
    not in the span of its first 12 modes, all bending."""
    v, f = plate
    params = ModalParams(n_modes=12, upper_thickness_factor=1.0, boundary="pinned", method="dense")
    basis = modal_basis(v, f, params)
    shape = np.sin(np.pi * v[:, 0] / A_MM) * np.sin(np.pi * v[:, 1] / A_MM)
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    bend, slide = np.zeros((len(v), 3)), np.zeros((len(v), 3))
    bend[:, 2], slide[:, 0] = shape, shape
    assert span_curve(basis.modes, bend, [1], normals).left[0] < 0.02
    assert span_curve(basis.modes, slide, [12], normals).left[0] > 0.99


def test_skin_stiffness_bad_input(plate):
    v, f = plate
    with pytest.raises(InputError, match="tension_n_per_mm"):
        skin_stiffness(v, f, -1.0)
    with pytest.raises(InputError, match="foundation_n_per_mm3"):
        skin_stiffness(v, f, 1.0, float("nan"))
    with pytest.raises(InputError, match="tethered"):
        skin_stiffness(v, f, 1.0, 0.0, np.ones(3, bool), 1.0)
    with pytest.raises(InputError, match="tether_normal_n_per_mm3"):
        skin_stiffness(v, f, 1.0, 0.0, None, 0.0, -0.5)


# --- presets and the store ---------------------------------------------------------------


SECTION = {"modes": 12, "semantic_labels": [], "reconstruction_k": [1, 5], "seed": 0}
TEMPLATE = {"subdivision_levels": 1}


def _config(modal_section):
    """A config with the modal section ``modal_section``."""
    return {"modal": modal_section, "template": TEMPLATE}


def test_presets_resolve_and_overrides_win():
    paper = modal.Params.from_config(_config(SECTION | {"preset": "paper"}))
    assert paper.fixed_outline == "all" and paper.modal.material.youngs_modulus_mpa == 210000.0
    assert paper.modal.upper_thickness_factor == 3.0 and not paper.modal.has_skin
    still = modal.Params.from_config(_config(SECTION | {"preset": "clamped_still"}))
    assert still.fixed_outline == "still" and still.modal == paper.modal
    skin = modal.Params.from_config(_config(SECTION))  # the default
    assert skin.physics["preset"] == modal.DEFAULT_PRESET == "skin"
    assert skin.fixed_outline == "every_still" and skin.tether_region == "still"
    assert skin.still_from == "expressions" and skin.modal.clamp_strip_mm == 6.0
    assert skin.modal.tension_n_per_mm == 1.0 and not skin.modal.material.rotary_inertia
    assert skin.modal.tether_normal_n_per_mm3 == 0.1 and skin.modal.coordinates == "vertex"
    assert paper.modal.coordinates == "mass" and paper.tether_region == "none"
    assert paper.still_from == "takes" and paper.modal.clamp_strip_mm == 0.0
    # the first skin preset, kept: clamped where the median take (visemes too) leaves the
    # outline still, free elsewhere
    v1 = modal.Params.from_config(_config(SECTION | {"preset": "skin_v1"}))
    assert (v1.fixed_outline, v1.still_from, v1.modal.clamp_strip_mm) == ("still", "takes", 0.0)
    assert v1.modal == replace(skin.modal, clamp_strip_mm=0.0)
    over = modal.Params.from_config(
        _config(SECTION | {"preset": "paper", "fixed_outline": "none", "thickness_mm": None})
    )
    assert over.fixed_outline == "none" and over.modal.thickness_mm == 1.0
    assert over.physics == paper.physics | {"fixed_outline": "none"}
    with pytest.raises(InputError, match="preset: expected one of"):
        modal.Params.from_config(_config(SECTION | {"preset": "rubber"}))
    with pytest.raises(InputError, match="fixed_outline"):
        modal.Params.from_config(_config(SECTION | {"fixed_outline": "some"}))
    with pytest.raises(InputError, match="tether_region"):
        modal.Params.from_config(_config(SECTION | {"tether_region": "chin"}))
    with pytest.raises(InputError, match="still_from: expected one of"):
        modal.Params.from_config(_config(SECTION | {"still_from": "visemes"}))
    for bad in (-1.0, "6", True, float("inf")):
        with pytest.raises(InputError, match="outline_strip_mm: expected a number >= 0"):
            modal.Params.from_config(_config(SECTION | {"outline_strip_mm": bad}))
    # the mimic skin's mass weighs a membrane's mass per area: a shell or equal vertex masses
    # would ignore it, so the config says so before any job runs
    heavier = {"mimic_mass_factor": 2.0}
    assert modal.Params.from_config(_config(SECTION | heavier)).modal.mimic_mass_factor == 2.0
    for other in ({"preset": "paper"}, {"youngs_modulus_mpa": 0.01}, {"mass": "vertex"}):
        with pytest.raises(
            InputError, match=r"config modal: mimic_mass_factor: 2.0 .* set it to 1"
        ):
            modal.Params.from_config(_config(SECTION | heavier | other))
    paper_plain = modal.Params.from_config(_config(SECTION | {"preset": "paper"}))
    assert paper_plain.modal.mimic_mass_factor == 1.0  # the paper's shell is untouched


def test_every_configuration_of_the_span_benchmark_is_one_the_stage_accepts():
    """``benchmarks/bench_modal_span.py`` measures every configuration of
    ``modal_span_variants.VARIANTS`` by default: each must resolve through the stage's own
    config checks (a variant the checks refuse stopped the whole benchmark), with its keys set
    on the stage's parameters."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "modal_span_variants.py"
    spec = importlib.util.spec_from_file_location("modal_span_variants", path)
    variants = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(variants)
    cfg = _config(SECTION)
    for name, variant in variants.VARIANTS.items():
        params = variants.variant_params(cfg, variant)
        expected = {k: v for k, v in variant.items() if k in params.physics}
        assert {k: params.physics[k] for k in expected} == expected, name
        strip = variant.get("clamp_strip_mm", params.physics["outline_strip_mm"])
        assert params.modal.clamp_strip_mm == float(strip), name


@pytest.fixture(scope="module")
def template():
    from scan2morph.template import build_template

    return build_template()


def _face(template):
    """The subdivided template lifted onto a dome (mm) and a smile-like displacement."""
    from scan2morph.template import subdivide_template

    fine = subdivide_template(template, 1)
    xy = fine.vertices * 40.0
    z = 90.0 * np.sqrt(np.clip(1 - (xy[:, 0] / 110) ** 2 - ((xy[:, 1] - 20) / 140) ** 2, 0, None))
    neutral = np.column_stack([xy[:, 0], -xy[:, 1], z])
    g = np.exp(-(((np.abs(xy[:, 0]) - 30) / 15) ** 2) - ((xy[:, 1] - 55) / 15) ** 2)
    smile = np.column_stack([2.0 * np.sign(xy[:, 0]) * g, 3.0 * g, 1.0 * g])
    return neutral, smile


@pytest.mark.parametrize("preset", ["skin", "paper"])
def test_the_stage_records_its_preset(template, preset):
    neutral, smile = _face(template)
    data = {paths.neutral("vertices"): neutral, paths.expression("sm1", "displacement"): smile}
    subject = Subject("s", {"n": "neutral", "sm1": "expression"}, {"n": "neutral", "sm1": "smile"})
    params = modal.Params.from_config(_config(SECTION | {"preset": preset}))
    part = modal.run(template, subject, data, params)
    d = part.datasets
    assert d[paths.modal("preset")] == preset
    assert json.loads(d[paths.modal("physics")]) == params.physics
    fixed = d[paths.modal("fixed_vertices")]
    outline = d[paths.modal("outline_vertices")]
    assert outline.sum() == len(template.boundary) * 2  # one subdivision doubles the loop
    assert not (fixed & ~outline).any()
    if preset == "paper":
        assert fixed.sum() == outline.sum()
    else:  # the outline where the smile moves the skin less than still_mm, at least a quarter
        moving = np.linalg.norm(smile, axis=1) >= 1.0
        assert 0.25 * outline.sum() <= fixed.sum() < outline.sum()
        assert not (fixed & moving).any() and (outline & moving).any()
    left = d[paths.expression("sm1", "reconstruction_rms_mm")][-1] / np.sqrt(
        np.mean(np.sum(smile**2, axis=1))
    )
    assert left < (0.8 if preset == "skin" else 1.0)
    # the reconstruction table's mode count is a count (the audit's F8: it read "83.0000")
    table = part.files["reconstruction"]
    assert str(table["modes_to_target"].dtype) == "Int64"
    count = d[paths.expression("sm1", "modes_to_target")]
    assert (
        table["modes_to_target"].isna().all()
        if np.isnan(count)
        else (table["modes_to_target"] == int(count)).all()
    )


def test_still_skin_is_where_every_take_stays_within_still_mm():
    from scan2morph.modal.boundary import still_skin

    a = np.zeros((5, 3))
    a[:, 0] = [0.2, 0.9, 1.5, np.nan, 0.0]
    b = np.zeros((5, 3))
    b[:, 1] = [0.5, 0.3, 0.1, np.nan, 2.0]
    assert still_skin([a, b], 5, 1.0).tolist() == [True, True, False, False, False]
    assert still_skin([a], 5, 2.0).tolist() == [True, True, True, False, True]
    assert not still_skin([], 5).any()
    with pytest.raises(InputError, match="field 1: expected shape"):
        still_skin([a, b[:4]], 5)
    with pytest.raises(InputError, match="still_mm"):
        still_skin([a], 5, -1.0)


def test_the_skin_is_tied_where_the_takes_leave_it_still(template):
    """tether_region still: the tie covers the vertices no take moves by still_mm (the
    template's stable face when there are no takes), and tying them puts the low modes on the
    moving skin: 12 modes rebuild more of the smile than the untied skin's."""
    from scan2morph.modal import modal_basis
    from scan2morph.template import subdivide_template
    from scan2morph.template.regions import stable_face

    fine = subdivide_template(template, 1)
    neutral, smile = _face(template)
    params = modal.Params.from_config(_config(SECTION))
    assert_allclose(modal.tethered(fine, params, [smile]), np.linalg.norm(smile, axis=1) < 1.0)
    assert (modal.tethered(fine, params, []) == stable_face(fine)).all()
    free = np.zeros(len(neutral), bool)
    normals = vertex_normals(neutral, fine.faces)
    left = []
    for tie in (modal.tethered(fine, params, [smile]), stable_face(fine), None):
        basis = modal_basis(neutral, fine.faces, params.modal, fixed=free, tethered=tie)
        left.append(span_curve(basis.modes, smile, [12], normals).left[0])
    assert left[0] < 0.8 * min(left[1:])  # 0.24 against 0.63 (stable face), 0.72


def test_vertex_mass_makes_the_stored_coordinates_least_squares(coarse_plate):
    """mass="vertex": the shell's mass shared equally by the vertices, so q = Q^T M v rebuilds
    exactly what least squares on the same modes does, at every K (the consistent mass weighs
    by area and differs on an uneven mesh)."""
    v, f = coarse_plate
    v = v.copy()
    v[:, 0] = A_MM * (v[:, 0] / A_MM) ** 1.6  # uneven spacing: dense near x = 0
    params = ModalParams(**(vars(membrane_params(15)) | {"mass": "vertex"}))
    basis = modal_basis(v, f, params, fixed=np.zeros(len(v), bool))
    m_diag = basis.mass.diagonal().reshape(-1, 6)
    total = RHO * H_MM * cotangent_laplacian(v, f)[1].sum()
    assert_allclose(m_diag[:, :3], total / len(v), rtol=1e-12) and not m_diag[:, 3:].any()
    rng = np.random.default_rng(2)
    field = np.column_stack([np.cos(v[:, 0] / 30.0 + c) for c in rng.normal(size=3)])
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    ks = [1, 4, 9, 15]
    ls = span_curve(basis.modes, field, ks, normals)
    q = project(basis, field)
    everywhere = np.ones(len(v), bool)
    stored = [
        residual_split(field - reconstruct(basis, q, k), normals, everywhere, ~everywhere)[0]
        for k in ks
    ]
    assert_allclose(stored, ls.total_mm, rtol=1e-8)
    consistent = modal_basis(v, f, membrane_params(15), fixed=np.zeros(len(v), bool))
    qc = project(consistent, field)
    err = residual_split(field - reconstruct(consistent, qc, 9), normals, everywhere, ~everywhere)
    lsc = span_curve(consistent.modes, field, [9], normals).total_mm[0]
    assert err[0] > 1.001 * lsc


def test_vertex_coordinates_are_least_squares_on_the_natural_modes_span(coarse_plate):
    """coordinates="vertex": the natural modes (consistent mass, uneven mesh) orthonormalised in
    order in the per-vertex inner product. Each leading set of K vectors spans what the first K
    natural modes span (least squares leaves the same), and the stored q = Q^T W v rebuilds
    exactly that least squares at every K; the mass coordinates of the same modes do not."""
    v, f = coarse_plate
    v = v.copy()
    v[:, 0] = A_MM * (v[:, 0] / A_MM) ** 1.6  # uneven spacing: dense near x = 0
    free = np.zeros(len(v), bool)
    natural = modal_basis(v, f, membrane_params(15), fixed=free)
    params = ModalParams(**(vars(membrane_params(15)) | {"coordinates": "vertex"}))
    basis = modal_basis(v, f, params, fixed=free)
    total = RHO * H_MM * cotangent_laplacian(v, f)[1].sum()
    assert_allclose(basis.mass.diagonal().reshape(-1, 6)[:, :3], total / len(v), rtol=1e-12)
    assert_allclose(basis.vectors.T @ (basis.mass @ basis.vectors), np.eye(15), atol=1e-9)
    assert basis.names == natural.names
    rng = np.random.default_rng(3)
    phase = rng.normal(size=3)
    field = np.column_stack([np.cos(v[:, 0] / 25.0 + c) * (1 + v[:, 1] / 90.0) for c in phase])
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    ks = [1, 4, 9, 15]
    ls = span_curve(natural.modes, field, ks, normals)
    assert_allclose(span_curve(basis.modes, field, ks, normals).total_mm, ls.total_mm, rtol=1e-7)
    everywhere = np.ones(len(v), bool)
    for k, z in zip(ks, ls.total_mm, strict=True):  # numpy's least squares
        direct = np.linalg.lstsq(natural.modes[:k].reshape(k, -1).T, field.ravel(), rcond=None)
        assert_allclose(z, np.sqrt(direct[1][0] / len(v)), rtol=1e-8)

    def stored(b):
        q = project(b, field)
        return [
            residual_split(field - reconstruct(b, q, k), normals, everywhere, ~everywhere)[0]
            for k in ks
        ]

    assert_allclose(stored(basis), ls.total_mm, rtol=1e-8)
    assert np.all(np.asarray(stored(natural)) > 1.0001 * ls.total_mm)
    with pytest.raises(InputError, match="coordinates"):
        modal_basis(v, f, ModalParams(**(vars(params) | {"coordinates": "area"})), fixed=free)
    twice = replace(natural, vectors=np.c_[natural.vectors, natural.vectors[:, :1]])
    with pytest.raises(InputError, match="translations are independent"):
        vertex_orthonormal(twice)


def test_reconstruction_figure_plots_the_share_left_and_names_the_preset():
    from scan2morph.render.modal_figures import fig_reconstruction

    d = np.zeros((10, 3))
    d[:, 0] = 2.0  # RMS 2 mm
    store = {
        paths.modal("reconstruction_k"): np.array([1, 10, 100]),
        paths.modal("preset"): "skin",
        paths.expression("sm1", "displacement"): d,
        paths.expression("sm1", "reconstruction_rms_mm"): np.array([1.6, 1.0, 0.4]),
        paths.expression("sm1", "reconstruction_normal_rms_mm"): np.array([0.6, 0.4, 0.2]),
    }
    fig = fig_reconstruction(store)
    ax = fig.axes[0]
    assert_allclose(ax.lines[0].get_ydata(), [0.8, 0.5, 0.2])
    assert_allclose(ax.lines[1].get_ydata(), [0.3, 0.2, 0.1])
    assert "preset skin" in ax.get_title() and "share" in ax.get_ylabel()


def test_report_names_the_preset():
    import h5py

    from scan2morph.report import sections

    with h5py.File("modal.h5", "w", driver="core", backing_store=False) as h5:
        h5[paths.modal("frequencies_hz")] = [10.0, 20.0]
        blocks = sections.modal(h5, 2)
        assert "preset" not in str(blocks[0])
        h5.create_dataset(paths.modal("preset"), data="paper", dtype=h5py.string_dtype())
        assert "physics: preset paper" in str(sections.modal(h5, 2)[0])


def robin_wavenumbers(strip_mm: float, a: float = A_MM) -> tuple[float, float]:
    """The two lowest wavenumbers (1/mm) of a string of length a whose ends are held by springs
    T / l (per unit length of the cut): X'' + k^2 X = 0, X' = X / l at x = 0 and X' = -X / l at
    x = a. Symmetric X = cos(k (x - a/2)): k l tan(k a / 2) = 1; antisymmetric
    X = sin(k (x - a/2)): tan(k a / 2) = -k l."""
    from scipy.optimize import brentq

    sym = brentq(lambda k: k * strip_mm * np.tan(k * a / 2) - 1.0, 1e-12, np.pi / a - 1e-12)
    anti = brentq(lambda k: np.tan(k * a / 2) + k * strip_mm, np.pi / a + 1e-9, 2 * np.pi / a)
    return float(sym), float(anti)


@pytest.mark.parametrize("strip_mm", [3.0, 10.0, 30.0])
def test_the_skin_beyond_the_cut_is_a_robin_edge(strip_mm):
    """A 100 mm square membrane (no shell) under T whose whole edge is held by a strip l wide
    (springs T L_i / l): its modes are products of the Robin strings' (k_x, k_y), omega^2 rho h
    = T (k_x^2 + k_y^2), each along x, y and z alike: the first three at (sym, sym), the next
    six at (sym, anti) and (anti, sym), within 1 % on a 24 x 24 grid. Between the clamp
    (l -> 0) and the free edge (l -> inf); the edge vertices move and are not fixed."""
    from scan2morph.modal.skin import edge_springs

    v, f = plate_mesh(24)
    params = ModalParams(
        n_modes=9,
        thickness_mm=H_MM,
        upper_thickness_factor=1.0,
        material=ShellMaterial(0.0, 0.3, RHO),
        tension_n_per_mm=T_N_PER_MM,
        method="block",
        clamp_strip_mm=strip_mm,
    )
    basis = modal_basis(v, f, params)
    sym, anti = robin_wavenumbers(strip_mm)
    speed = np.sqrt(T_N_PER_MM / (RHO * H_MM)) / (2 * np.pi)
    exact = speed * np.array([np.hypot(sym, sym)] * 3 + [np.hypot(sym, anti)] * 6)
    assert_allclose(basis.frequencies_hz, exact, rtol=0.01)
    clamped = speed * np.pi / A_MM * np.sqrt(2)
    assert 0 < basis.frequencies_hz[0] < clamped
    rim = boundary_vertices(f, len(v))
    assert not basis.fixed_vertices.any()
    assert np.abs(basis.modes[:3, rim]).max() > 0.05 * np.abs(basis.modes[:3]).max()
    # the springs: T L_i / l on each translation, L_i half the rim edges at vertex i
    k = edge_springs(v, f, rim, T_N_PER_MM, strip_mm).diagonal().reshape(-1, 6)
    assert_allclose(k[:, 3:], 0.0)
    assert_allclose(k[:, :3].sum() / 3, T_N_PER_MM * 4 * A_MM / strip_mm)
    assert_allclose(k[0, :3], T_N_PER_MM * A_MM / 24 / strip_mm)  # a corner: two half edges


def test_the_strip_needs_a_tension_and_a_positive_width(coarse_plate):
    """Bad strips are refused; a strip 1e-4 mm wide holds the edge as the clamp does."""
    v, f = coarse_plate
    with pytest.raises(InputError, match="clamp_strip_mm"):
        modal_basis(v, f, replace(membrane_params(3), tension_n_per_mm=0.0, clamp_strip_mm=5.0))
    with pytest.raises(InputError, match="clamp_strip_mm"):
        modal_basis(v, f, replace(membrane_params(3), clamp_strip_mm=-1.0))
    # a vanishing strip is the clamp
    clamp = modal_basis(v, f, membrane_params(3))
    stiff = modal_basis(v, f, replace(membrane_params(3), clamp_strip_mm=1e-4))
    assert_allclose(stiff.frequencies_hz, clamp.frequencies_hz, rtol=1e-3)


def test_one_side_held_by_the_skin_beyond_the_cut_the_others_clamped():
    """A 100 mm square membrane clamped on three sides and held on the fourth (x = a) by a
    strip l wide (a :class:`Held`): its modes are sin(k x) sin(pi y / a) with tan(k a) = -k l
    (X(0) = 0, X'(a) = -X(a) / l), omega^2 rho h = T (k^2 + (pi / a)^2), along x, y and z
    alike: the first three within 1 % on a 24 x 24 grid, between the square clamped all round
    and the one free on that side; the sprung side moves and is not fixed."""
    from scipy.optimize import brentq

    v, f = plate_mesh(24)
    rim = boundary_vertices(f, len(v))
    side = rim & np.isclose(v[:, 0], A_MM) & (v[:, 1] > 1e-9) & (v[:, 1] < A_MM - 1e-9)
    params = replace(membrane_params(3), clamp_strip_mm=10.0)
    basis = modal_basis(v, f, params, fixed=Held(rim & ~side, side))
    k = brentq(lambda x: np.tan(x * A_MM) + x * 10.0, np.pi / (2 * A_MM) + 1e-9, np.pi / A_MM)
    speed = np.sqrt(T_N_PER_MM / (RHO * H_MM)) / (2 * np.pi)
    assert_allclose(basis.frequencies_hz, speed * np.hypot(k, np.pi / A_MM), rtol=0.01)
    assert speed * np.hypot(0.5, 1.0) * np.pi / A_MM < basis.frequencies_hz[0]  # free side
    assert basis.frequencies_hz[0] < speed * np.sqrt(2) * np.pi / A_MM  # clamped all round
    assert not (basis.fixed_vertices & side).any() and (basis.fixed_vertices == rim & ~side).all()
    assert np.abs(basis.modes[:3, side]).max() > 0.1 * np.abs(basis.modes[:3]).max()


def test_a_held_boundary_is_checked(coarse_plate):
    """Springs need a strip, lie on the boundary, and the masks have the mesh's shape."""
    v, f = coarse_plate
    rim = boundary_vertices(f, len(v))
    none = np.zeros(len(v), bool)
    with pytest.raises(InputError, match="sprung: the skin beyond the cut needs a clamp_strip_mm"):
        modal_basis(v, f, membrane_params(3), fixed=Held(none, rim))
    strip = replace(membrane_params(3), clamp_strip_mm=5.0)
    with pytest.raises(InputError, match="sprung: vertex .* is not on the mesh's boundary"):
        modal_basis(v, f, strip, fixed=Held(rim, ~rim))
    with pytest.raises(InputError, match=rf"clamped: expected a \({len(v)},\) bool mask"):
        modal_basis(v, f, strip, fixed=Held(rim[:-1], none))
    # no springs: the clamped vertices alone, as a plain mask gives them
    plain = modal_basis(v, f, membrane_params(3), fixed=rim)
    held = modal_basis(v, f, membrane_params(3), fixed=Held(rim, none))
    assert_allclose(held.frequencies_hz, plain.frequencies_hz, rtol=1e-12)


def test_every_still_clamps_only_the_outline_no_take_moves():
    """``every_still`` clamps an outline vertex when the largest of the takes' displacements
    there is below still_mm; ``still`` when the median is. One take of three moving a stretch
    of the loop unclamps it under the first only."""
    from scan2morph.modal.boundary import outline_motion, still_outline

    n = 40
    loop = np.arange(n)
    takes = [np.zeros((n, 3)) for _ in range(3)]
    takes[0][10:20, 1] = 2.0  # one take moves vertices 10-19 by 2 mm
    takes[1][:, 0] = 0.3
    median = still_outline(loop, takes, n, "still", 1.0, 0.25)
    every = still_outline(loop, takes, n, "every_still", 1.0, 0.25)
    assert median.fixed.all()
    assert every.fixed.tolist() == [not 10 <= i < 20 for i in range(n)]
    assert_allclose(every.motion_mm[12:18], 2.0) and assert_allclose(median.motion_mm, 0.0)
    assert_allclose(outline_motion(loop, takes, n, reduce="max")[:5], 0.3)
    with pytest.raises(InputError, match="reduce: expected"):
        outline_motion(loop, takes, n, reduce="mean")
    # at least min_fixed_share stays clamped, the stillest
    takes[2][:, 2] = 5.0
    takes[2][:4, 2] = 1.5
    least = still_outline(loop, takes, n, "every_still", 1.0, 0.1)
    assert least.fixed.sum() == 4 and least.fixed[:4].all()


def test_the_skin_preset_takes_its_stillness_from_the_expressions(template):
    """With ``still_from: expressions`` a viseme that moves the chin's outline (the jaw) neither
    unclamps it nor unties the skin there; with ``takes`` it does. The outline the expressions
    move is held by the strip's springs (not clamped, not free)."""
    from scan2morph.template import subdivide_template

    fine = subdivide_template(template, 1)
    neutral, smile = _face(template)
    jaw = np.zeros_like(smile)
    low = neutral[:, 1] < np.percentile(neutral[:, 1], 20)  # the lowest fifth of the face
    jaw[low, 1] = -6.0
    data = {
        paths.neutral("vertices"): neutral,
        paths.expression("sm1", "displacement"): smile,
        paths.viseme("car", "motion"): jaw,
    }
    kinds = {"n": "neutral", "car": "viseme", "sm1": "expression"}
    subject = Subject("s", kinds, {"n": "neutral", "car": "car", "sm1": "smile"})
    fields = {"sm1": smile}
    skin = modal.Params.from_config(_config(SECTION))
    takes = modal.Params.from_config(_config(SECTION | {"still_from": "takes"}))
    assert len(modal.still_fields(subject, data, fields, skin)) == 1
    assert len(modal.still_fields(subject, data, fields, takes)) == 2
    assert len(modal.still_fields(subject, data, {}, skin)) == 1  # no expressions: every take
    outline = np.zeros(fine.n_vertices, bool)
    outline[fine.boundary] = True
    chin = outline & low & (np.linalg.norm(smile, axis=1) < 0.5)
    assert chin.sum() >= 4
    by_expr = modal.outline_choice(fine, subject, data, fields, skin)
    by_takes = modal.outline_choice(fine, subject, data, fields, takes)
    assert by_expr.fixed[chin].all() and not by_takes.fixed[chin].any()
    tie_expr = modal.tethered(fine, skin, modal.still_fields(subject, data, fields, skin))
    tie_takes = modal.tethered(fine, takes, modal.still_fields(subject, data, fields, takes))
    assert tie_expr[chin].all() and not tie_takes[chin].any()
    hold = modal.held(by_expr, skin)
    assert (hold.sprung == outline & ~by_expr.fixed).all() and hold.sprung.any()
    basis, _ = modal.natural_basis(fine, subject, data, fields, skin)
    assert (basis.fixed_vertices[fine.boundary] == by_expr.fixed[fine.boundary]).all()
    assert np.abs(basis.modes[:, hold.sprung]).max() > 0
