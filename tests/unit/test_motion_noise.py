"""Tests of scan2morph.motion.uncertainty: the click-noise error bar of the viseme motion."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from scan2morph.align.rigid import transform_points
from scan2morph.errors import InputError
from scan2morph.motion.model import AlignedMesh, VisemeSmoothing, viseme_motion
from scan2morph.motion.uncertainty import (
    ClickedTake,
    ClickNoise,
    DrawRecipe,
    click_noise_motion,
    noise_datasets,
)
from scan2morph.store import read_part, write_part
from scan2morph.template import FitRules, build_template, fit_take, noise_gain
from scan2morph.template.regions import named_indices
from tests.support.configs import repo_config

W, H = 640, 480
#: d(xyz)/dx, d(xyz)/dy (mm per px) and the offset of a tilted plane seen by the scanner.
PLANE = np.array([[0.7, 0.0, 0.05], [0.0, 0.7, -0.03], [-224.0, -168.0, 1000.0]])
SHIFT_MM = np.array([0.0, 0.0, 5.0])
FIT = FitRules(levels=0, min_valid_fraction=0.1, max_fold_fraction=0.01, min_weight=1.0)
NO_SMOOTHING = {"w": 0.1, "iterations": 0, "max_stretch": 2.0, "confidence_relief": 0.5}


@pytest.fixture(scope="module")
def template():
    return build_template()


@pytest.fixture(scope="module")
def takes(template):
    """A neutral on the plane and a viseme that is the same scan moved 5 mm along z."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    xyz = np.stack([x, y, np.ones_like(x)], axis=-1) @ PLANE
    landmarks = np.array([320.0, 230.0]) + 70.0 * template.ibug_xy
    moved = np.eye(4)
    moved[:3, 3] = SHIFT_MM
    neutral = ClickedTake(xyz, landmarks, "closed", np.eye(4))
    return neutral, {"she": ClickedTake(xyz, landmarks, "closed", moved)}


def _run(template, takes, **kw):
    neutral, visemes = takes
    args = {
        "suppressed": np.zeros(len(template.vertices), bool),
        "smoothing": NO_SMOOTHING,
        "fit_rules": FIT,
        "click_noise_px": 0.5,
        "draws": 8,
        "seed": 1,
    }
    args.update(kw)
    recipe = DrawRecipe(args["fit_rules"], args["smoothing"], args.get("refiner"))
    noise = ClickNoise(args["click_noise_px"], args["draws"], args["seed"])
    return click_noise_motion(template, neutral, visemes, args["suppressed"], recipe, noise, "subj")


def test_error_bar_matches_the_spline_noise_gain_on_a_plane(template, takes):
    """On a plane linear in the pixel coordinates a vertex moves by the 2D warp error times the
    plane's Jacobian A: both takes' independent clicks give sigma * gain * sqrt(2) * |A|_F."""
    sigma = 0.5
    res = _run(template, takes, click_noise_px=sigma, draws=600)["she"]
    _, idx = template.fiducial_set("closed")
    gain = noise_gain(template.vertices[idx], template.vertices)
    expected = sigma * gain * np.sqrt(2.0) * np.linalg.norm(PLANE[:2])
    ratio = res["rms_mm"] / expected
    assert abs(np.median(ratio) - 1.0) < 0.03
    assert np.all(np.abs(ratio - 1.0) < 0.15)
    assert res["motion_rms_mm"] == pytest.approx(5.0, rel=1e-9)
    rms = np.sqrt(np.mean(expected**2))
    assert res["relative"] == pytest.approx(rms / 5.0, rel=0.03)
    assert res["failed_draws"] == 0


def test_error_bar_scales_with_the_click_noise(template, takes):
    """On the plane the fit is linear in the clicks and one seed draws the same unit noise at
    any size: four times the click noise is four times the error bar (measured to 1e-14, with
    20 draws as with 200)."""
    small = _run(template, takes, click_noise_px=0.25, draws=20)["she"]["rms_error_mm"]
    large = _run(template, takes, click_noise_px=1.0, draws=20)["she"]["rms_error_mm"]
    assert large / small == pytest.approx(4.0, rel=1e-6)


def test_masked_vertices_carry_no_error_and_smoothing_is_the_pipelines(template, takes):
    mask = template.vertices[:, 1] > np.median(template.vertices[:, 1])
    res = _run(
        template,
        takes,
        suppressed=mask,
        smoothing={"w": 0.1, "iterations": 30, "max_stretch": 2.0, "confidence_relief": 0.5},
    )
    assert_array_equal(res["she"]["rms_mm"][mask], 0.0)
    assert (res["she"]["rms_mm"][~mask] > 0).all()
    # smoothing averages neighbouring errors: the spread drops below the unsmoothed one
    raw = _run(template, takes, suppressed=mask)
    assert res["she"]["rms_error_mm"] < raw["she"]["rms_error_mm"]


def test_same_seed_same_numbers_other_seed_other_numbers(template, takes):
    a, b = _run(template, takes, seed=3), _run(template, takes, seed=3)
    c = _run(template, takes, seed=4)
    assert_array_equal(a["she"]["rms_mm"], b["she"]["rms_mm"])
    assert not np.array_equal(a["she"]["rms_mm"], c["she"]["rms_mm"])


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"click_noise_px": 0.0}, "click_noise_px: expected > 0"),
        ({"click_noise_px": float("nan")}, "click_noise_px: expected > 0"),
        ({"draws": 1}, "draws: expected an integer >= 2"),
        ({"draws": 2.5}, "draws: expected an integer >= 2"),
        ({"suppressed": np.zeros(3, bool)}, r"suppressed: expected \(441,\)"),
    ],
)
def test_bad_input_is_named(template, takes, kw, match):
    with pytest.raises(InputError, match=match):
        _run(template, takes, **kw)


def test_a_take_the_noise_folds_has_no_error_bar_and_the_others_theirs(template, takes, caplog):
    """A viseme whose clicks lie close together (a small face) folds the template under a
    click noise the others take: it has no error bar (NaN, every draw refused, a warning naming
    it and quoting the first refusal) and the others' are as without it, bit for bit (it used
    to stop the subject). A noise that folds the neutral leaves every viseme without one."""
    neutral, visemes = takes
    small = np.array([320.0, 230.0]) + 10.0 * template.ibug_xy
    eel = replace(visemes["she"], landmarks=small)
    both = _run(template, (neutral, visemes | {"eel": eel}), click_noise_px=2.0)
    alone = _run(template, takes, click_noise_px=2.0)
    assert_array_equal(both["she"]["rms_mm"], alone["she"]["rms_mm"])
    assert both["she"]["failed_draws"] == 0 and np.isfinite(both["she"]["relative"])
    assert both["eel"]["failed_draws"] == 8
    assert np.isnan(both["eel"]["rms_mm"]).all() and np.isnan(both["eel"]["relative"])
    assert np.isnan(both["eel"]["rms_error_mm"])
    motion = both["eel"]["motion"]  # its motion's RMS all the same (no mask here)
    rms = np.sqrt(np.mean(np.sum(motion[np.isfinite(motion).all(axis=1)] ** 2, axis=1)))
    assert both["eel"]["motion_rms_mm"] == pytest.approx(rms, rel=1e-12) and rms > 0
    assert re.search(
        r"subj/eel has no click-noise error bar: click_noise_px 2: only \d of 8 perturbed fits "
        r"of eel succeeded .*first refusal, draw \d+: subj/eel: landmarks fold",
        caplog.text,
    )
    folded = _run(template, takes, click_noise_px=60.0)["she"]
    assert folded["failed_draws"] == 8 and np.isnan(folded["relative"])
    assert "perturbed fits of neutral succeeded" in caplog.text


def test_a_bad_take_is_named(template, takes):
    neutral, visemes = takes
    bad = ClickedTake(visemes["she"].xyz, visemes["she"].landmarks[:67], "closed", np.eye(4))
    with pytest.raises(InputError, match=r"subj/she.*landmarks: expected \(68, 2\)"):
        _run(template, (neutral, {"she": bad}))


def test_a_subject_without_visemes_gets_empty_datasets(template, takes, tmp_path):
    """No viseme takes: nothing to perturb, and the empty result still round-trips the store."""
    neutral, _ = takes
    suppressed = np.zeros(len(template.vertices), bool)
    recipe, noise = DrawRecipe(FIT, NO_SMOOTHING), ClickNoise(0.5, 4, 1)
    result = click_noise_motion(template, neutral, {}, suppressed, recipe, noise)
    assert result == {}
    write_part(tmp_path / "part.h5", noise_datasets(result))
    back = read_part(tmp_path / "part.h5")
    assert back["/motion_noise/takes"].shape == (0,)
    assert back["/motion_noise/relative"].shape == (0,)


def test_store_datasets_follow_the_result_order(template, takes, tmp_path):
    neutral, visemes = takes
    both = {"too": visemes["she"], "she": visemes["she"]}
    result = _run(template, (neutral, both), draws=3)
    data = noise_datasets(result)
    write_part(tmp_path / "part.h5", data)
    back = read_part(tmp_path / "part.h5")
    assert list(back["/motion_noise/takes"]) == ["too", "she"]
    assert back["/motion_noise/failed_draws"].tolist() == [0, 0]
    assert back["/motion_noise/relative"].tolist() == [
        result[t]["relative"] for t in ("too", "she")
    ]
    assert_array_equal(back["/visemes/she/noise_rms_mm"], result["she"]["rms_mm"])


def test_reference_motion_is_the_pipelines_and_takes_do_not_share_noise(template, takes):
    """The unperturbed motion equals viseme_motion's (same mask, same smoothing); a take's
    numbers do not depend on the other takes (each has its own noise stream)."""
    neutral, visemes = takes
    meshes = {}
    for name, take in (("neutral", neutral), ("she", visemes["she"])):
        mesh = fit_take(template, take.landmarks, take.xyz, (W, H), "closed", FIT)
        aligned = transform_points(take.transform, mesh["vertices"])
        meshes[name] = AlignedMesh(aligned, mesh["valid"])
    paths = named_indices(template, [["temple_r", "temple_l"]], "mask.paths")
    stored = viseme_motion(
        meshes["neutral"],
        {"she": meshes["she"]},
        template.faces,
        paths,
        VisemeSmoothing(20.0, 0.1, 30, max_stretch=2.0),
        "subj",
    )
    smoothing = {"w": 0.1, "iterations": 30, "max_stretch": 2.0, "confidence_relief": 0.5}
    mask = stored["/mask/suppressed"]
    assert 0 < mask.sum() < len(mask)
    alone = _run(template, takes, suppressed=mask, smoothing=smoothing)["she"]
    assert_allclose(alone["motion"], stored["/visemes/she/motion"], atol=1e-12)
    two = {"car": visemes["she"], "she": visemes["she"]}
    both = _run(template, (neutral, two), suppressed=mask, smoothing=smoothing)
    assert_array_equal(both["she"]["rms_mm"], alone["rms_mm"])
    assert not np.array_equal(both["car"]["rms_mm"], alone["rms_mm"])


def test_a_take_with_the_pipelines_motion_is_not_refitted_for_the_reference(template, takes):
    """Given its motion (as the stage reads it from the store), a take's reference is that
    motion: the same numbers as the refit gives, and a different motion moves the spread."""
    neutral, visemes = takes
    refitted = _run(template, takes)["she"]
    given = {"she": replace(visemes["she"], motion=refitted["motion"].copy())}
    again = _run(template, (neutral, given))["she"]
    assert_array_equal(again["motion"], refitted["motion"])
    assert_array_equal(again["rms_mm"], refitted["rms_mm"])
    off = {"she": replace(visemes["she"], motion=refitted["motion"] + [0.0, 0.0, 0.3])}
    moved = _run(template, (neutral, off))["she"]
    assert np.nanmin(moved["rms_mm"]) > 0.25  # the spread is measured around the given motion


def test_the_table_states_its_rms_is_over_the_unmasked_vertices(template, takes):
    """tables/motion_noise.tsv's motion RMS is over the vertices outside the mask; the cohort's
    motion_rms_all_mm_{label} is over all of them, so the two differ and are named apart."""
    from scan2morph.report.cohort import motion_rms
    from scan2morph.stages import motion_noise
    from scan2morph.tables import MOTION_NOISE, describe

    mask = template.vertices[:, 1] > np.median(template.vertices[:, 1])
    res = _run(template, takes, suppressed=mask, draws=3)["she"]
    free = res["motion"][~mask]
    unmasked = np.sqrt(np.mean(np.sum(free**2, axis=1)))
    assert res["motion_rms_mm"] == pytest.approx(unmasked, rel=1e-12)
    assert motion_rms(res["motion"]) < 0.9 * unmasked  # over all vertices: the masked ones too
    assert motion_noise.COLUMNS == {
        "motion_rms_mm": "motion_rms_unmasked_mm",
        "rms_error_mm": "noise_rms_unmasked_mm",
        "relative": "noise_relative_unmasked",
        "failed_draws": "failed_draws",
    }
    names = ["take", *motion_noise.COLUMNS.values(), "click_noise_px_used"]
    assert [c.name for c in describe(names, MOTION_NOISE)] == names


def test_a_refiner_that_finds_the_skin_whatever_the_clicks_leaves_only_the_neutrals_noise(
    template, takes
):
    """With a refiner the draw's motion is the refined take's: a refiner that recovers the
    take's true vertices from any clicks (the skin itself says where it went) leaves only the
    neutral's click noise, sqrt(2) less than both takes' (the oracle of the first test)."""
    neutral, visemes = takes
    seen = []

    def exact(take, fit, take_landmarks, neutral_landmarks):
        seen.append(np.array(take_landmarks))
        mesh = fit_take(
            template, neutral.landmarks, neutral.xyz, rules=FitRules(levels=0)
        )  # the true points
        # confidence 0: smoothed as the plain run is, so that its oracle holds
        zero = np.zeros(len(mesh["valid"]))
        return transform_points(visemes[take].transform, mesh["vertices"]), mesh["valid"], zero

    plain = _run(template, takes, draws=100)["she"]["rms_error_mm"]
    refined = _run(template, takes, draws=100, refiner=exact)["she"]["rms_error_mm"]
    assert refined == pytest.approx(plain / np.sqrt(2.0), rel=0.1)
    # every draw hands the refiner its own perturbed clicks (and the reference the clicked ones)
    assert_array_equal(seen[0], visemes["she"].landmarks)
    assert len({s.tobytes() for s in seen}) == len(seen) == 101


def test_a_draw_the_refinement_refuses_is_left_out_not_the_subject(template, takes):
    """The refine stage refuses a detected take whose fit is not its skin (it leaves its
    subject); in the click-noise draws such a refusal leaves that draw out and is counted, and
    the subject's error bar stands on the others (a review found it stopping the subject's
    job). The draws' numbers are those of the same refiner that refuses nothing, without that
    draw."""
    neutral, visemes = takes
    calls = []

    def refiner(refuse):
        def refine(take, fit, take_landmarks, neutral_landmarks):
            calls.append(refuse)
            if refuse and sum(calls) == 3:  # the reference, then the second draw
                raise InputError("subj/she", "it would move the skin 9.1 mm RMS")
            return fit["vertices"], fit["valid"], None

        return refine

    kept = _run(template, takes, draws=8, refiner=refiner(True))["she"]
    every = _run(template, takes, draws=8, refiner=refiner(False))["she"]
    assert kept["failed_draws"] == 1 and every["failed_draws"] == 0
    assert np.isfinite(kept["rms_error_mm"]) and kept["rms_error_mm"] > 0
    assert_array_equal(kept["motion"], every["motion"])


def test_a_refiners_confidence_shortens_the_smoothing_of_the_draws(template, takes):
    """The draws are smoothed as the pipeline smooths: with a refiner that measured every vertex
    (confidence 1) and a relief of 1, 30 smoothing steps leave a bumpy motion unsmoothed; at
    confidence 0 they smooth it."""
    neutral, visemes = takes

    def refiner(confidence):
        def refine(take, fit, take_landmarks, neutral_landmarks):
            mesh = fit_take(template, neutral.landmarks, neutral.xyz, rules=FitRules(levels=0))
            v = transform_points(visemes[take].transform, mesh["vertices"])
            bumps = np.random.default_rng(3).normal(0.0, 0.5, v.shape)  # what smoothing removes
            return v + bumps, mesh["valid"], np.full(len(v), confidence)

        return refine

    smooth = {"w": 0.1, "iterations": 30, "max_stretch": 2.0, "confidence_relief": 1.0}
    unsmoothed = _run(template, takes, draws=2, refiner=refiner(0.0))["she"]["motion"]
    sure = _run(template, takes, draws=2, refiner=refiner(1.0), smoothing=smooth)["she"]
    unsure = _run(template, takes, draws=2, refiner=refiner(0.0), smoothing=smooth)["she"]
    assert_allclose(sure["motion"], unsmoothed, atol=1e-12)
    assert np.abs(unsure["motion"] - unsmoothed).max() > 0.01  # mm: smoothed


@pytest.mark.parametrize(
    ("verdict", "expected"),
    [({}, [False, True, True]), ({"she": True}, [True, True, True]), ({"she": False}, [False] * 3)],
)
def test_the_draws_follow_the_pipelines_verdict_on_the_texture(monkeypatch, verdict, expected):
    """A viseme the pipeline refined by the surface's shape (its texture did not correlate:
    the refine part's ``shape_used``) is refined by the shape straight away in every draw, the
    first too; one it refined by the texture tries the texture in every draw (whatever a draw
    finds); without the pipeline's verdict the first draw's decides for the others."""

    from scan2morph.stages import motion_noise
    from scan2morph.stages import refine as refine_stage
    from scan2morph.stages.part import Part, Subject
    from scan2morph.store import paths

    skipped = []

    def run(template, take, params):
        skipped.append(params.texture_unmatched)
        out = {paths.refine("she", k): np.zeros(3) for k in ("vertices", "valid", "confidence")}
        # the texture does not correlate in any draw
        return Part(out, attrs={paths.refine_group("she"): {"shape_used": True}})

    monkeypatch.setattr(refine_stage, "run", run)
    config = repo_config()
    params = refine_stage.Params.from_config(config)
    subject = Subject("s", {"neutral": "neutral", "she": "viseme"}, {"neutral": "n", "she": "s"})
    data = {paths.align("she", "transform"): np.eye(4)}
    refiner = motion_noise._refiner(None, subject, data, params, verdict)
    mesh = {"valid": np.ones(3, bool), "points2d": np.zeros((3, 2)), "vertices": np.zeros((3, 3))}
    for _ in range(3):
        refiner("she", mesh, np.zeros((68, 2)), np.zeros((68, 2)))
    assert skipped == expected
    attrs = {"she": {"shape_used": np.True_}, "car": {"shape_used": False}, "eel": {}}
    data = {paths.refine_group(t): a for t, a in attrs.items()}
    verdicts = motion_noise.shape_verdicts(data, ["she", "car", "eel", "man"])
    assert verdicts == {"she": True, "car": False}


def test_a_visemes_reference_places_its_rim_from_the_neutrals_clicks(template, takes):
    """With ``rim_share`` < 1 the reference motion is the pipeline's fit with the viseme's
    forehead rim placed from the neutral's clicks (:class:`~scan2morph.template.rim.Rim`): a
    viseme whose brows were clicked 6 px higher moves as the two fits the stage makes say, and
    not as the plain splines do."""
    from scan2morph.template.rim import BROWS, Rim

    neutral, visemes = takes
    raised = visemes["she"].landmarks.copy()
    raised[np.array(BROWS) - 1, 1] -= 6.0
    she = replace(visemes["she"], landmarks=raised)
    no_mask = np.zeros(len(template.vertices), bool)
    n_mesh = fit_take(template, neutral.landmarks, neutral.xyz, (W, H), "closed", FIT)
    motions = {}
    for share in (0.5, 1.0):
        rim = Rim(neutral.landmarks, "closed", share) if share < 1 else None
        mesh = fit_take(template, raised, she.xyz, (W, H), "closed", FIT, rim=rim)
        motions[share] = transform_points(she.transform, mesh["vertices"]) - n_mesh["vertices"]
        recipe = DrawRecipe(FIT, NO_SMOOTHING, rim_share=share)
        got = click_noise_motion(
            template, neutral, {"she": she}, no_mask, recipe, ClickNoise(0.5, 2, 1), "subj"
        )["she"]["motion"]
        assert_allclose(got, motions[share], atol=1e-9)
    assert np.max(np.abs(motions[0.5] - motions[1.0])) > 1.0


def test_detected_landmarks_say_the_noise_is_the_detectors_scatter_not_its_bias():
    """The click-noise note names how many takes' landmarks were detected (their
    ``landmark_detected`` in the store) and that the measured noise is not the detector's
    bias; with only clicked takes it adds nothing."""
    from scan2morph.motion.uncertainty import detected_note
    from scan2morph.store import paths

    takes = ["neutral", "car", "too"]
    assert detected_note({}, takes) == ""
    store = {paths.landmark_detected(t): np.zeros((68, 2)) for t in ("neutral", "too")}
    note = detected_note(store, takes)
    assert note.startswith("; 2 of 3 takes' landmarks were detected")
    assert "not its bias" in note
