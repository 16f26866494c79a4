"""Tests of scan2morph.morph: blend shapes (Eq. 1) and PCA (Eq. 2, Tables 1-3)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from scan2morph.errors import InputError
from scan2morph.morph import (
    ALPHA_LIMIT,
    DEFAULT_BLENDS,
    DEFAULT_PCA_BLENDS,
    PCAModel,
    blend,
    contribution_rates,
    pca,
    pca_tables,
    project,
    synthesize,
)
from scan2morph.morph.frame import apply_frame, head_frame
from scan2morph.morph.pca import SIGMA_CONVENTIONS
from scan2morph.morph.subject import (
    parse_pca_target,
    pca_component_targets,
    pca_target_sigmas,
    pca_target_weights,
)
from scan2morph.template import build_template

# The paper's Table 1 (eigenvalue, CR, CCR) and Table 2 (coefficients, rows: base, too, man,
# she, eel, car; columns omega_1..omega_5), as printed.
TABLE1_EIGEN = np.array([124912.0, 20496.0, 8513.0, 5596.0, 1437.0])
TABLE1_CR = [(0.776, 3), (0.127, 3), (0.053, 3), (0.035, 3), (0.0089, 4)]
TABLE1_CCR = [(0.776, 3), (0.903, 3), (0.956, 3), (0.991, 3), (1.0, 1)]
TABLE2 = np.array(
    [
        [-184.7, -65.2, -33.7, -35.1, -0.1],
        [-82.65, 105.7, -38.2, 16.5, 4.4],
        [114.0, 34.6, 22.3, -31.6, -25.0],
        [-78.3, 8.9, 68.9, -3.2, 17.8],
        [-22.0, -53.6, 5.9, 55.5, -13.9],
        [253.7, -30.5, -25.2, -2.1, 16.8],
    ]
)
NAMES = ("neutral", "too", "man", "she", "eel", "car")


def _face_set(seed: int, m: int = 6, v: int = 300, rank: int | None = None) -> np.ndarray:
    """M shapes of V vertices ~1000 mm from the origin: a face plus ``rank`` deformation modes
    of decreasing amplitude (default: generic, rank M - 1 after centring)."""
    rng = np.random.default_rng(seed)
    face = np.array([1000.0, -400.0, 1500.0]) + rng.normal(scale=60.0, size=(v, 3))
    rank = m if rank is None else rank
    modes = rng.normal(size=(rank, v, 3))
    amplitude = 10.0 / (1.0 + np.arange(rank)) ** 1.5  # mm
    coeff = rng.normal(size=(m, rank)) * amplitude
    return face + np.tensordot(coeff, modes, axes=1)


# ----------------------------------------------------------------------------- blend shapes


def _blend_inputs(seed=1, v=50):
    rng = np.random.default_rng(seed)
    base = rng.normal(scale=50.0, size=(v, 3)) + 1000.0
    shapes = {name: base + rng.normal(scale=5.0, size=(v, 3)) for name in NAMES[1:]}
    return base, shapes


def test_blend_unit_weight_gives_the_viseme_exactly_and_no_weight_the_base():
    base, shapes = _blend_inputs()
    for name, shape in shapes.items():
        assert_array_equal(blend(base, shapes, {name: 1.0}), shape)
    assert_array_equal(blend(base, shapes, {}), base)
    assert_array_equal(blend(base, shapes, {"car": 0.0}), base)


def test_blend_matches_equation_1_for_the_paper_mixtures():
    base, shapes = _blend_inputs(2)
    for name, weights in DEFAULT_BLENDS.items():
        expected = (
            sum(w * shapes[k] for k, w in weights.items()) + (1.0 - sum(weights.values())) * base
        )
        assert_allclose(blend(base, shapes, weights), expected, rtol=0, atol=1e-10, err_msg=name)
    # Fig. 12 left: 0.6 man + 0.3 eel + 0.1 base, written the way the caption writes it.
    left = blend(base, shapes, DEFAULT_BLENDS["man60_eel30"])
    assert_allclose(left, 0.6 * shapes["man"] + 0.3 * shapes["eel"] + 0.1 * base, atol=1e-10)


def test_fig11_series_is_linear_in_the_weight():
    base, shapes = _blend_inputs(3)
    for viseme in ("car", "eel", "too"):
        s = [blend(base, shapes, DEFAULT_BLENDS[f"{viseme}_{p}"]) for p in (30, 60, 90)]
        step = shapes[viseme] - base
        assert_allclose(s[1] - s[0], 0.3 * step, atol=1e-10)
        assert_allclose(s[2] - s[1], 0.3 * step, atol=1e-10)
        assert_allclose(s[0] - base, 0.3 * step, atol=1e-10)


def test_default_blends_are_the_papers():
    assert {k: v for k, v in DEFAULT_BLENDS.items() if len(v) == 1} == {
        f"{vis}_{p}": {vis: p / 100} for vis in ("car", "eel", "too") for p in (30, 60, 90)
    }
    assert DEFAULT_BLENDS["man60_eel30"] == {"man": 0.6, "eel": 0.3}
    assert DEFAULT_BLENDS["too50_car20"] == {"too": 0.5, "car": 0.2}
    assert DEFAULT_BLENDS["too80_eel10_car10"] == {"too": 0.8, "eel": 0.1, "car": 0.1}
    assert len(DEFAULT_BLENDS) == 12


def test_blend_accepts_a_stacked_array_with_names():
    base, shapes = _blend_inputs(4)
    stack = np.stack(list(shapes.values()))
    out = blend(base, stack, {"man": 0.6, "eel": 0.3}, names=list(shapes))
    assert_allclose(out, blend(base, shapes, {"man": 0.6, "eel": 0.3}), atol=0)
    assert_array_equal(blend(base, stack, {"2": 1.0}), stack[2])


@pytest.mark.parametrize(
    ("weights", "match"),
    [
        ({"car": -0.1}, r"weights\['car'\] = -0\.1.*non-negative"),
        ({"car": float("nan")}, r"weights\['car'\].*finite"),
        ({"car": "a lot"}, r"weights\['car'\]"),
        ({"car": 0.6, "too": 0.5}, r"sum to 1\.1 > 1"),
        ({"ah": 0.5}, r"unknown viseme 'ah'.*\['car', 'eel', 'man', 'she', 'too'\]"),
    ],
)
def test_blend_rejects_bad_weights(weights, match):
    base, shapes = _blend_inputs()
    with pytest.raises(InputError, match=match):
        blend(base, shapes, weights, source="s1/blend")


def test_blend_accepts_weights_summing_to_one_within_slack():
    base, shapes = _blend_inputs()
    out = blend(base, shapes, {"too": 0.8, "eel": 0.1, "car": 0.1 + 5e-10})
    assert np.isfinite(out).all()


def test_blend_rejects_bad_shapes():
    base, shapes = _blend_inputs()
    with pytest.raises(InputError, match=r"s1/blend: base: expected a \(V, 3\)"):
        blend(base[:, :2], shapes, {}, source="s1/blend")
    bad = dict(shapes, car=shapes["car"][:-1])
    with pytest.raises(InputError, match=r"shapes\['car'\]: expected 50 vertices"):
        blend(base, bad, {"too": 0.5})
    nan = dict(shapes, eel=shapes["eel"].copy())
    nan["eel"][7, 1] = np.nan
    with pytest.raises(InputError, match=r"shapes\['eel'\]: 1 vertices .*index 7"):
        blend(base, nan, {"too": 0.5})
    with pytest.raises(InputError, match=r"names: expected 5 names"):
        blend(base, np.stack(list(shapes.values())), {}, names=["a"])
    with pytest.raises(InputError, match=r"shapes: expected a mapping"):
        blend(base, base, {})


# ----------------------------------------------------------------------------- PCA


def test_gram_pca_matches_svd_of_the_centred_data():
    shapes = _face_set(10)
    model = pca(shapes, NAMES)
    m = shapes.shape[0]
    centred = (shapes - shapes.mean(axis=0)).reshape(m, -1)
    u, s, vt = np.linalg.svd(centred, full_matrices=False)  # independent oracle
    k = model.n_components
    assert k == m - 1
    assert_allclose(model.eigenvalues, s[:k] ** 2, rtol=1e-8)
    comps = model.components.reshape(k, -1)
    sign = np.sign(np.sum(comps * vt[:k], axis=1))
    assert_array_equal(np.abs(sign), 1.0)
    assert_allclose(comps, sign[:, None] * vt[:k], rtol=0, atol=1e-8 * np.abs(vt[:k]).max())
    assert_allclose(model.coefficients, u[:, :k] * s[:k] * sign, rtol=0, atol=1e-8 * s[0])
    assert_allclose(model.mean, shapes.mean(axis=0), rtol=1e-15)
    assert model.names == NAMES


def test_pca_follows_the_papers_convention_and_is_orthonormal():
    shapes = _face_set(11)
    model = pca(shapes)
    # C = X'X'^T without 1/M: eigenvalue_i = sum over shapes of coefficient_i squared.
    assert_allclose(model.eigenvalues, np.sum(model.coefficients**2, axis=0), rtol=1e-10)
    comps = model.components.reshape(model.n_components, -1)
    assert_allclose(comps @ comps.T, np.eye(model.n_components), atol=1e-12)
    assert np.all(np.diff(model.eigenvalues) < 0)
    # The coefficients of centred data sum to zero over the shapes.
    assert_allclose(model.coefficients.sum(axis=0), 0, atol=1e-9 * np.sqrt(model.eigenvalues[0]))
    assert model.ccr[-1] == 1.0
    assert_allclose(model.cr.sum(), 1.0, rtol=1e-14)
    assert_allclose(np.cumsum(model.cr), model.ccr, rtol=1e-14)
    # Deterministic sign: each component's largest-magnitude entry is positive.
    pivots = comps[np.arange(len(comps)), np.argmax(np.abs(comps), axis=1)]
    assert np.all(pivots > 0)
    assert model.names == ("0", "1", "2", "3", "4", "5")


def test_reconstruction_from_all_components_is_exact_and_project_matches():
    shapes = _face_set(12)
    model = pca(list(shapes), NAMES)
    rebuilt = model.mean + np.tensordot(model.coefficients, model.components, axes=1)
    assert_allclose(rebuilt, shapes, rtol=0, atol=1e-9)
    for j, shape in enumerate(shapes):
        assert_allclose(project(model, shape), model.coefficients[j], rtol=0, atol=1e-9)


def test_synthesis_follows_equation_2():
    shapes = _face_set(13)
    model = pca(shapes, sigma="paper")  # Eq. 2 as printed: sigma_i = sqrt(lambda_i)
    assert_array_equal(synthesize(model, np.zeros(model.n_components)), model.mean)
    assert_array_equal(synthesize(model, []), model.mean)
    # alpha_i = omega_i / sqrt(lambda_i) rebuilds an input shape (|alpha| <= 1 by construction).
    alpha = model.coefficients[3] / np.sqrt(model.eigenvalues)
    assert np.all(np.abs(alpha) <= 1.0)
    assert_allclose(synthesize(model, alpha), shapes[3], rtol=0, atol=1e-9)
    # One component at alpha moves the mean by alpha * sqrt(lambda) along e (a 3V unit vector).
    out = synthesize(model, [0.0, -2.5])
    assert_allclose(out - model.mean, -2.5 * np.sqrt(model.eigenvalues[1]) * model.components[1])
    assert_allclose(np.linalg.norm(out - model.mean), 2.5 * np.sqrt(model.eigenvalues[1]))
    assert_allclose(
        project(model, out), [0, -2.5 * np.sqrt(model.eigenvalues[1]), 0, 0, 0], atol=1e-9
    )


def test_default_pca_blends_are_table_3_and_synthesize():
    assert DEFAULT_PCA_BLENDS == {
        "pca_blend1": (0.5, 1.0, 0.0),
        "pca_blend2": (1.0, 0.0, -2.0),
        "pca_blend3": (-0.5, -0.9, 0.9),
    }
    model = pca(_face_set(14), sigma="paper")
    for alpha in DEFAULT_PCA_BLENDS.values():
        out = synthesize(model, alpha)
        assert_allclose(
            project(model, out)[:3], np.array(alpha) * np.sqrt(model.eigenvalues[:3]), atol=1e-9
        )


def test_sigma_is_the_sample_std_of_the_coefficients_by_default():
    shapes = _face_set(21)
    model = pca(shapes)
    m = shapes.shape[0]
    assert model.sigma_convention == "sample"
    assert_allclose(model.sigma, np.std(model.coefficients, axis=0, ddof=1), rtol=1e-12)
    assert_allclose(model.sigma, np.sqrt(model.eigenvalues / (m - 1)), rtol=1e-10)
    # the eigenvalues stay the paper's (no 1/M): Table 1 is unchanged by the convention
    paper = pca(shapes, sigma="paper")
    assert paper.sigma_convention == "paper"
    assert_allclose(paper.sigma, np.sqrt(paper.eigenvalues), rtol=1e-15)
    assert_array_equal(paper.eigenvalues, model.eigenvalues)
    assert_allclose(paper.sigma / model.sigma, np.sqrt(m - 1), rtol=1e-10)
    # synthesis and the tables follow the model's convention
    out = synthesize(model, [0.0, 3.0])
    assert_allclose(project(model, out)[:2], [0.0, 3.0 * model.sigma[1]], atol=1e-9)
    rows, _ = pca_tables(model)
    assert list(rows[0]) == ["component", "eigenvalue", "cr", "ccr", "sigma_sample_mm"]
    assert_allclose([r["sigma_sample_mm"] for r in rows], model.sigma, rtol=0)
    assert "sigma_paper_mm" in pca_tables(paper)[0][0]
    with pytest.raises(InputError, match=r"morph.sigma: 'population' unknown"):
        pca(shapes, sigma="population")


def test_pca_target_weights_are_never_negative_zero():
    """An alpha of 0 (or -0.0, as ``-np.zeros`` gives) weighs both its targets +0.0: a -0.0
    printed or written reads as a negative shape-key value."""
    weights = pca_target_weights([0.0, -0.0, 1.5, -1.5])
    assert weights["pca_3_pos"] == 0.5 and weights["pca_4_neg"] == 0.5
    assert not any(np.signbit(w) for w in weights.values()), weights


def test_pca_targets_add_up_to_the_synthesis():
    """neutral + sum_k w_k (target_k - neutral) is Eq. 2 for several weights at once."""
    shapes = _face_set(22)
    neutral = shapes[0]
    for convention in SIGMA_CONVENTIONS:
        model = pca(shapes, sigma=convention)
        targets = pca_component_targets(model, neutral)
        pairs = [f"pca_{k + 1}_{s}" for k in range(5) for s in ("pos", "neg")]
        assert list(targets) == ["pca_mean", *pairs]
        assert_allclose(targets["pca_mean"], model.mean, rtol=0)
        alpha = np.array([1.0, -0.7, 0.0, 3.0])
        weights = pca_target_weights(alpha)
        assert weights == {
            "pca_mean": 1.0,
            **{"pca_1_pos": 1 / 3, "pca_1_neg": 0.0, "pca_2_pos": 0.0},
            **{"pca_2_neg": pytest.approx(0.7 / 3), "pca_3_pos": 0.0, "pca_3_neg": 0.0},
            **{"pca_4_pos": 1.0, "pca_4_neg": 0.0},
        }
        morphed = neutral + sum(w * (targets[k] - neutral) for k, w in weights.items())
        assert_allclose(morphed, synthesize(model, alpha), rtol=0, atol=1e-9)
        # each component target alone moves the neutral by 3 sigma_k along +-e_k, not by the mean
        for sign, name in ((1, "pca_2_pos"), (-1, "pca_2_neg")):
            step = targets[name] - neutral
            assert_allclose(step, sign * 3 * model.sigma[1] * model.components[1], atol=1e-12)
        assert pca_target_sigmas(2) == {
            "pca_1_pos": 3.0,
            "pca_1_neg": -3.0,
            "pca_2_pos": 3.0,
            "pca_2_neg": -3.0,
        }
        assert [parse_pca_target(n) for n in ("pca_2_neg", "pca_10_pos", "pca_1", "pca_x_pos")] == [
            (2, -1.0),
            (10, 1.0),
            None,
            None,
        ]


def test_rank_deficient_data_keeps_only_the_nonzero_components():
    shapes = _face_set(15, m=7, rank=2)  # 7 shapes spanning a 2-D affine family: rank <= 2
    model = pca(shapes)
    assert model.n_components == 2
    assert model.coefficients.shape == (7, 2)
    assert model.ccr[-1] == 1.0
    rebuilt = model.mean + np.tensordot(model.coefficients, model.components, axes=1)
    assert_allclose(rebuilt, shapes, rtol=0, atol=1e-9)


def test_two_shapes_give_one_component():
    shapes = _face_set(16, m=2)
    model = pca(shapes)
    assert model.n_components == 1
    half = 0.5 * (shapes[1] - shapes[0])
    assert_allclose(model.eigenvalues[0], 2 * np.sum(half**2), rtol=1e-12)
    assert_allclose(np.abs(model.coefficients[:, 0]), np.linalg.norm(half), rtol=1e-12)


def test_pca_scales_with_the_gram_matrix_not_3v_by_3v():
    # V = 200k: a 3V x 3V covariance would need 2.9 TB; the M x M Gram matrix is 6 x 6.
    rng = np.random.default_rng(17)
    v = 200_000
    shapes = 1000.0 + rng.normal(size=(1, v, 3)) + rng.normal(scale=0.5, size=(6, v, 3))
    model = pca(shapes)
    assert model.components.shape == (5, v, 3)
    assert_allclose(model.eigenvalues, np.sum(model.coefficients**2, axis=0), rtol=1e-10)


def test_model_arrays_are_read_only():
    model = pca(_face_set(18))
    assert isinstance(model, PCAModel)
    with pytest.raises(ValueError, match="read-only"):
        model.mean[0, 0] = 0.0
    with pytest.raises(AttributeError):
        model.mean = None


def test_contribution_rates_reproduce_table_1():
    cr, ccr = contribution_rates(TABLE1_EIGEN)
    for value, (printed, digits) in zip(cr, TABLE1_CR, strict=True):
        assert round(value, digits) == pytest.approx(printed, abs=1e-12)
    for value, (printed, digits) in zip(ccr, TABLE1_CCR, strict=True):
        assert round(value, digits) == pytest.approx(printed, abs=1e-12)
    assert ccr[-1] == 1.0


def test_table_2_is_consistent_with_table_1_in_the_papers_convention():
    # Column sums of squares of the printed coefficients equal the printed eigenvalues
    # (C without 1/M), within the effect of rounding the coefficients to 0.1 (|dw| <= 0.05):
    # |d sum w^2| <= sum 2 |w| 0.05 + 6 * 0.05^2.
    bound = np.sum(2 * np.abs(TABLE2) * 0.05, axis=0) + 6 * 0.05**2
    assert np.all(np.abs(np.sum(TABLE2**2, axis=0) - TABLE1_EIGEN) <= bound)
    # And the coefficients of centred data sum to zero over the six models.
    assert np.all(np.abs(TABLE2.sum(axis=0)) <= 6 * 0.05)


def test_pca_tables_rows():
    model = pca(_face_set(19), NAMES)
    eigen_rows, coef_rows = pca_tables(model)
    assert [r["component"] for r in eigen_rows] == [1, 2, 3, 4, 5]
    assert_allclose([r["eigenvalue"] for r in eigen_rows], model.eigenvalues, rtol=0)
    assert_allclose([r["ccr"] for r in eigen_rows], model.ccr, rtol=0)
    assert_allclose([r["cr"] for r in eigen_rows], model.cr, rtol=0)
    assert [r["take"] for r in coef_rows] == list(NAMES)
    assert list(coef_rows[0]) == ["take", "w1", "w2", "w3", "w4", "w5"]
    assert_allclose([[r[f"w{i}"] for i in range(1, 6)] for r in coef_rows], model.coefficients)
    assert all(type(r["eigenvalue"]) is float for r in eigen_rows)


def test_pca_accepts_a_mapping():
    shapes = _face_set(20)
    model = pca(dict(zip(NAMES, shapes, strict=True)))
    assert model.names == NAMES
    assert_allclose(model.eigenvalues, pca(shapes).eigenvalues, rtol=1e-14)


def test_pca_rejects_bad_input():
    shapes = _face_set(21)
    with pytest.raises(InputError, match=r"s1: shapes: PCA needs at least two shapes, got 1"):
        pca(shapes[:1], source="s1")
    ragged = [shapes[0], shapes[1][:-3], shapes[2]]
    with pytest.raises(InputError, match=r"shapes\[1\] \('1'\): has 297 vertices, expected 300"):
        pca(ragged)
    nan = shapes.copy()
    nan[4, 12, 2] = np.nan
    with pytest.raises(InputError, match=r"shapes\[4\] \('eel'\): 1 vertices .*index 12"):
        pca(nan, NAMES)
    with pytest.raises(InputError, match=r"shapes: expected an \(M, V, 3\) array"):
        pca(shapes[0])
    with pytest.raises(InputError, match=r"shapes\[0\] \('0'\): expected a \(V, 3\)"):
        pca(shapes[:, :, :2])
    with pytest.raises(InputError, match=r"names: expected 6 names"):
        pca(shapes, ["a", "b"])
    with pytest.raises(InputError, match=r"all 3 shapes are identical"):
        pca(np.repeat(shapes[:1], 3, axis=0))
    with pytest.raises(InputError, match=r"names: give names either"):
        pca({"a": shapes[0], "b": shapes[1]}, ["x", "y"])


def test_synthesize_and_project_reject_bad_input():
    model = pca(_face_set(22))
    with pytest.raises(
        InputError, match=r"alpha\[2\] \(component 3\) = 3\.5: expected within \[-3, 3\]"
    ):
        synthesize(model, [0.0, 1.0, 3.5])
    with pytest.raises(InputError, match=r"alpha\[0\] .* = nan"):
        synthesize(model, [np.nan])
    with pytest.raises(InputError, match=r"alpha: 6 values but the model has 5 components"):
        synthesize(model, np.zeros(6))
    with pytest.raises(InputError, match=r"alpha: expected a \(K,\) array"):
        synthesize(model, np.zeros((1, 2)))
    assert synthesize(model, [3.0, -3.0]).shape == (300, 3)  # the bounds are inclusive
    assert ALPHA_LIMIT == 3.0
    assert synthesize(model, [4.0], alpha_limit=5.0).shape == (300, 3)
    with pytest.raises(InputError, match=r"shape: expected \(300, 3\), got \(299, 3\)"):
        project(model, model.mean[:-1])
    bad = model.mean.copy()
    bad[0, 0] = np.inf
    with pytest.raises(InputError, match=r"shape: contains non-finite"):
        project(model, bad)


@pytest.mark.parametrize(
    ("eigenvalues", "match"),
    [
        ([], r"expected a non-empty \(K,\) array"),
        ([[1.0, 2.0]], r"expected a non-empty \(K,\) array"),
        ([1.0, -2.0], r"finite non-negative"),
        ([1.0, np.nan], r"finite non-negative"),
        ([0.0, 0.0], r"all zero"),
    ],
)
def test_contribution_rates_reject_bad_input(eigenvalues, match):
    with pytest.raises(InputError, match=match):
        contribution_rates(eigenvalues)


# ----------------------------------------------------------------------------- head frame

UNIT_MM = 45.0  # canonical template unit: half the outer-eye distance


def _canonical_face():
    """The template as a face in a head-like frame (mm): x = subject's left, y up, z out of the
    face; flat except for a nose up to 25 mm high (eyes and mouth corners at depth 0)."""
    template = build_template()
    u, v = template.vertices[:, 0], template.vertices[:, 1]
    nose = 25.0 * np.clip(1.0 - (u**2 + (v - 0.9) ** 2) / 0.1, 0.0, None) ** 2  # compact
    return template, np.column_stack([UNIT_MM * u, -UNIT_MM * v, nose])


def _rigid(rng):
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot *= np.sign(np.linalg.det(rot))  # a proper rotation: scanner frames are right-handed
    return rot, rng.normal(0, 800.0, 3)


def test_head_frame_is_orthonormal_right_handed_and_frame_independent():
    template, face = _canonical_face()
    named = template.named
    eyes = face[[named[n] for n in ("eye_r_outer", "eye_r_inner", "eye_l_inner", "eye_l_outer")]]
    expected = 1e-3 * (face - eyes.mean(axis=0))  # the canonical frame is the head frame here
    rng = np.random.default_rng(30)
    for _ in range(4):
        rot, shift = _rigid(rng)  # an arbitrary scanner frame: no axis is up or forward
        scanner = face @ rot.T + shift
        h = head_frame(scanner, named)
        r = h[:3, :3] / 1e-3
        assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
        assert_array_equal(h[3], [0, 0, 0, 1])
        head = apply_frame(h, scanner)
        assert_allclose(head, expected, atol=1e-12)  # metres, whatever the scanner frame
        eye_y = head[[named["eye_r_outer"], named["eye_l_outer"]], 1].mean()
        mouth_y = head[[named["mouth_r"], named["mouth_l"]], 1].mean()
        assert eye_y - mouth_y > 0.07  # eyes 77 mm above the mouth corners
        assert head[named["eye_l_outer"], 0] > 0.04 > -0.04 > head[named["eye_r_outer"], 0]
        assert head[named["nose_tip"], 2] > 0.015  # the nose points to +Z (the viewer)
        assert np.ptp(head[:, 0]) == pytest.approx(0.14, abs=0.03)  # a face across, metres


def test_head_frame_rejects_a_mirrored_face_and_missing_points():
    template, face = _canonical_face()
    with pytest.raises(InputError, match="mirrored"):
        head_frame(face * [1.0, 1.0, -1.0], template.named)
    with pytest.raises(InputError, match=r"missing: \['nose_tip'\]"):
        head_frame(face, {k: i for k, i in template.named.items() if k != "nose_tip"})
