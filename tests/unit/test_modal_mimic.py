"""Tests of the skin varying over the face (scan2morph.modal.skin): the mimic weight, a softer or
heavier region of a membrane, and the stage's mimic skin.

Analytic oracles: a square membrane under tension T with mass rho h per area vibrates at
``omega = sqrt(T / (rho h)) k``; scaling T (or rho h) everywhere scales every frequency by the
square root (or its inverse); a clamped membrane whose central square is 100 times softer has
its first modes in that square, at (just below) the square's own clamped-membrane frequency
``sqrt(T_s / (rho h)) pi sqrt(2) / b`` (the square's clamped first mode extended by zero is a
trial function of the whole membrane: an upper bound).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from scan2morph.errors import InputError
from scan2morph.modal import ModalParams, ShellMaterial, modal_basis
from scan2morph.modal.skin import face_field, mimic_skin, mimic_weight, vertex_field
from scan2morph.stages import modal
from tests.support.meshes import plate_mesh

A_MM, T_N_PER_MM, RHO, H_MM = 100.0, 1.0, 1.1e-9, 1.0


def membrane(n_modes: int, **factors) -> ModalParams:
    """A 1 mm membrane (no shell) under 1 N/mm; ``factors``: mimic_*_factor."""
    return ModalParams(
        n_modes=n_modes,
        thickness_mm=H_MM,
        upper_thickness_factor=1.0,
        material=ShellMaterial(0.0, 0.3, RHO),
        tension_n_per_mm=T_N_PER_MM,
        method="block",
        **factors,
    )


def free_hz(m: int, n: int, tension: float = T_N_PER_MM, rho_h: float = RHO * H_MM) -> float:
    """Free square membrane, mode cos(m pi x / a) cos(n pi y / a)."""
    k = np.pi / A_MM * np.hypot(m, n)
    return float(np.sqrt(tension / rho_h) * k / (2 * np.pi))


@pytest.fixture(scope="module")
def plate():
    return plate_mesh(16)


@pytest.mark.parametrize(("tension", "mass"), [(0.25, 1.0), (1.0, 4.0), (0.5, 2.0)])
def test_a_uniformly_softer_or_heavier_membrane_scales_its_frequencies(plate, tension, mass):
    """Weight 1 everywhere: the factors act on the whole membrane, omega = sqrt(f T / (g rho h))
    k for every mode, in plane and out of plane alike."""
    v, f = plate
    free = np.zeros(len(v), bool)
    params = membrane(18, mimic_tension_factor=tension, mimic_mass_factor=mass)
    basis = modal_basis(v, f, params, fixed=free, mimic=np.ones(len(v)))
    exact = [
        free_hz(m, n, tension * T_N_PER_MM, mass * RHO * H_MM) for m, n in [(1, 0), (1, 1), (2, 0)]
    ]
    assert_allclose(basis.frequencies_hz[3:18], np.repeat(exact, [6, 3, 6]), rtol=0.02)
    plain = modal_basis(v, f, membrane(18), fixed=free)
    assert_allclose(
        basis.frequencies_hz[3:], plain.frequencies_hz[3:] * np.sqrt(tension / mass), rtol=1e-6
    )


@pytest.mark.parametrize("kind", ["tension", "mass"])
def test_the_first_modes_of_a_clamped_membrane_live_in_its_soft_square(kind):
    """A 100 mm clamped membrane whose central 50 mm square is 100 times softer (tension / 100)
    or heavier (mass x 100): the wave speed there is a tenth, and the first three modes (x, y,
    z) have more than 97% of their kinetic energy in the square (a fifth of the vertices), below the
    square's own clamped (1, 1) frequency (the upper bound). Softer: at 0.9-1.0 of it (the stiff
    surroundings nearly clamp the square). Heavier: the square moves nearly as one mass on the
    tensioned surroundings, lower still."""
    v, f = plate_mesh(24)
    soft = ((np.abs(v[:, :2] - A_MM / 2) <= A_MM / 4 + 1e-9).all(axis=1)).astype(float)
    factors = {"tension": {"mimic_tension_factor": 0.01}, "mass": {"mimic_mass_factor": 100.0}}
    basis = modal_basis(v, f, membrane(6, **factors[kind]), mimic=soft)
    square_hz = free_hz(1, 1, 0.01 * T_N_PER_MM, RHO * H_MM) * 2.0  # side a / 2, Dirichlet (1, 1)
    assert_allclose(basis.frequencies_hz[:3], basis.frequencies_hz[0], rtol=1e-6)
    assert basis.frequencies_hz[0] <= 1.001 * square_hz
    assert basis.frequencies_hz[0] > (0.9 if kind == "tension" else 0.3) * square_hz
    rho = 1.0 + (100.0 - 1.0) * soft if kind == "mass" else np.ones(len(v))
    motion = rho * np.sum(basis.modes[:3] ** 2, axis=2)
    assert np.all(motion[:, soft > 0].sum(axis=1) / motion.sum(axis=1) > 0.97)
    assert soft.mean() < 0.3


def test_a_softer_foundation_lowers_the_normal_modes_only_there(plate):
    """Foundation factor 0.25 everywhere: the normal modes' omega^2 rho h = T k^2 + k_n / 4; the
    in-plane ones keep theirs."""
    v, f = plate
    kn = T_N_PER_MM * (np.pi / A_MM) ** 2 * 3.0
    params = replace(membrane(12, mimic_foundation_factor=0.25), foundation_n_per_mm3=kn)
    basis = modal_basis(v, f, params, fixed=np.zeros(len(v), bool), mimic=np.ones(len(v)))
    along_z = np.sum(basis.modes[:, :, 2] ** 2, axis=1) / np.sum(basis.modes**2, axis=(1, 2))
    normal = basis.frequencies_hz[along_z > 0.99]
    want = np.sqrt(kn / 4 / (RHO * H_MM)) / (2 * np.pi)
    assert_allclose(normal[0], want, rtol=0.02)


def test_mimic_weight_is_a_gaussian_of_the_distance_to_the_nearest_line():
    """Distance to a segment (ends and middle), the largest over lines, bad input."""
    line = np.array([[0.0, 0.0], [2.0, 0.0]])
    pts = np.array([[1.0, 0.0], [1.0, 1.0], [3.0, 0.0], [-1.0, 1.0], [10.0, 10.0]])
    w = mimic_weight(pts, [(line, 1.0)])
    d = np.array([0.0, 1.0, 1.0, np.sqrt(2.0), np.hypot(8.0, 10.0)])
    assert_allclose(w, np.exp(-0.5 * d**2), atol=1e-12)
    two = mimic_weight(pts, [(line, 1.0), (np.array([[10.0, 9.0], [10.0, 11.0]]), 0.5)])
    assert two[-1] == 1.0 and np.all(two[:-1] == w[:-1])
    with pytest.raises(InputError, match="width"):
        mimic_weight(pts, [(line, 0.0)])
    with pytest.raises(InputError, match="line 0"):
        mimic_weight(pts, [(line[:1], 1.0)])
    with pytest.raises(InputError, match="factor"):
        vertex_field(1.0, -1.0, w)
    assert face_field(2.0, 0.5, w, np.array([[0, 1, 2]])) == pytest.approx(
        2.0 * (1 - 0.5 * w[:3].mean())
    )


def test_the_template_mimic_skin_covers_mouth_cheeks_brows_and_forehead_not_the_nose(template):
    """On the subdivided template: weight 1 at the mouth corners, the inner brows and the
    forehead's centre, above 0.5 between a mouth corner and its cheekbone, below 0.05 on the
    nose ridge, below 0.3 on the chin; the stage passes it only when a factor is not 1."""
    from scan2morph.template import subdivide_template

    fine = subdivide_template(template, 1)
    w = mimic_skin(fine)
    n = fine.named
    ends = ["mouth_r", "mouth_l", "brow_r_inner", "brow_l_inner", "forehead_centre"]
    assert_allclose(w[[n[k] for k in ends]], 1.0)
    xy = fine.vertices[:, :2]
    cheek = 0.5 * (xy[n["mouth_r"]] + xy[n["cheekbone_r"]])
    assert w[np.argmin(np.linalg.norm(xy - cheek, axis=1))] > 0.5
    assert w[n["nose_mid"]] < 0.05 and w[n["chin"]] < 0.3
    cfg = {"template": {"subdivision_levels": 1}}
    base = {"modes": 10, "seed": 0, "semantic_labels": [], "reconstruction_k": [1]}
    plain = modal.Params.from_config(cfg | {"modal": base | {"preset": "paper"}})
    assert modal.mimic(fine, plain) is None
    soft = modal.Params.from_config(
        cfg | {"modal": base | {"preset": "skin", "mimic_tension_factor": 0.5}}
    )
    assert_allclose(modal.mimic(fine, soft), w)


@pytest.fixture(scope="module")
def template():
    from scan2morph.template import build_template

    return build_template()
