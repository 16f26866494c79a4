"""The landmarks stage: clicked takes pass through, doubtful detections warn."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.landmarks import fit_chin
from scan2morph.stages import fit, landmarks
from scan2morph.stages.part import Take
from scan2morph.stages.quality import subject_warnings
from scan2morph.store import paths, write_part
from scan2morph.synth.cohort import make_take
from scan2morph.template import build_template
from tests.support.configs import repo_config

SETTINGS = {
    "min_valid_fraction": 0.0,
    "include_failed_takes": False,
    "max_click_noise_px": 1.0,
    "max_view_turn_deg": 15.0,
    "max_clipped_share": 0.25,
    "max_noise_mm": 0.25,
}


@pytest.fixture(scope="module")
def car():
    """A 320 x 240 car take (read-only: shared by the module's tests)."""
    r = make_take("s1", "car", "viseme", "car", 3, {"width": 320, "height": 240, "focal_px": 725.0})
    for key in ("xyz", "color", "landmarks"):
        r[key].setflags(write=False)
    return r


def test_a_clicked_take_keeps_its_clicks(car):
    r = car
    data = {
        paths.range_image("car", "xyz"): r["xyz"],
        paths.range_image("car", "color"): r["color"],
        paths.clicks("car"): r["landmarks"],
    }
    take = Take("s1", "car", "viseme", "car", "neutral", data)
    part = landmarks.run(None, take, landmarks.Params())
    np.testing.assert_array_equal(part.datasets[paths.landmarks("car")], r["landmarks"])
    assert part.datasets[paths.landmark_info("car", "source")] == "clicked"
    assert part.datasets[paths.landmark_info("car", "detector")] == ""
    assert part.datasets[paths.landmark_info("car", "doubtful")] == ""
    assert paths.landmark_confidence("car") not in part.datasets
    np.testing.assert_array_equal(part.files["pts"], r["landmarks"])
    # the handedness check ran on them: the nose tip stands out towards the scanner
    assert part.attrs[paths.take("car")]["nose_depth_mm"] < -5.0


def test_low_confidence_is_doubtful_and_a_warning(tmp_path):
    points = np.zeros((68, 2))
    sure = landmarks.Landmarks(points, landmarks.DETECTED, np.full(68, 0.9), "d", "1")
    unsure = landmarks.Landmarks(points, landmarks.DETECTED, np.full(68, 0.2), "d", "1")
    assert sure.doubtful(0.5) == ""
    message = unsure.doubtful(0.5)
    assert "median confidence 0.20 below 0.5" in message
    assert landmarks.Landmarks(points, landmarks.CLICKED).doubtful(0.5) == ""
    path = tmp_path / "store.h5"
    write_part(
        path,
        {
            paths.landmark_info("a", "doubtful"): message,
            paths.landmark_info("b", "doubtful"): "",
            paths.align("a", "ok"): True,
            paths.align("b", "ok"): True,
        },
    )
    with h5py.File(path) as h5:
        warnings = subject_warnings(h5, SETTINGS)
    assert [(w.stage, w.take) for w in warnings] == [("landmarks", "a")]
    assert "doubtful" in warnings[0].message


DOUBTFUL = "the detected landmarks are doubtful"
#: A take's refinement that followed its skin (the refine group's attributes).
REFINED = {"confident_share": 0.568, "median_correction_px": 4.26, "used": True}


def _doubtful_subject(viseme: str, source: str) -> tuple[dict, dict]:
    """A store's datasets and attributes: the neutral ``n`` and the expression ``s`` detected
    and doubtful (``s`` refined by its texture, :data:`REFINED`), a viseme whose landmarks came
    from ``source`` (doubtful when detected)."""
    sources = {"n": "detected", "s": "detected", viseme: source}
    data = {paths.landmark_info(t, "source"): src for t, src in sources.items()}
    data |= {
        paths.landmark_info(t, "doubtful"): DOUBTFUL if src == "detected" else ""
        for t, src in sources.items()
    }
    data |= {paths.align(t, "ok"): True for t in sources}
    data |= {paths.refine("s", "valid"): np.ones(3, bool)}
    attrs = {paths.take("n"): {"kind": "neutral"}, paths.take("s"): {"kind": "expression"}}
    attrs |= {paths.take(viseme): {"kind": "viseme"}, paths.refine_group("s"): REFINED}
    return data, attrs


def _said(path, data: dict, attrs: dict) -> dict[str, str]:
    """The subject's warnings by take, of a store written with ``data`` and ``attrs``."""
    write_part(path, data, attrs=attrs)
    with h5py.File(path) as h5:
        return {w.take: w.message for w in subject_warnings(h5, SETTINGS)}


def test_a_doubtful_warning_says_what_the_error_does(tmp_path):
    """The neutral's doubtful points place the template; another take's error is taken up
    where its refinement followed the skin (its share and median correction, from the refine
    group's attributes); without a refinement nothing is added."""
    message = DOUBTFUL
    data, attrs = _doubtful_subject("v", "detected")
    path = tmp_path / "store.h5"
    said = _said(path, data, attrs)
    assert said["n"].startswith(message + "; the neutral's points place the template")
    assert said["s"] == (
        message + "; its refinement (by its texture) measured where its skin went on 57% of the "
        "face, a median 4.3 px from the landmarks' fit: there the take's own detection error is "
        "taken up"
    )
    assert said["v"] == message
    # refined by the surface's shape, it says so; moved by the takes' consensus, the
    # consensus's numbers are the ones that count (motion reads its mesh)
    shape = REFINED | {"shape_used": True}
    consensus = {"confident_share": 0.81, "median_correction_px": 1.94}
    for extra, expected in (
        ({paths.refine_group("s"): shape}, "its refinement (by the surface's shape) measured where "
         "its skin went on 57% of the face, a median 4.3 px"),
        ({paths.refine_group("s"): shape, paths.consensus_group("s"): consensus}, "the takes' "
         "consensus (their shared texture) measured where its skin went on 81% of the face, a "
         "median 1.9 px"),
    ):  # fmt: skip
        said = _said(path, data, attrs | extra)
        assert said["s"].startswith(message + "; " + expected), said["s"]


def test_params_from_the_whole_config():
    params = landmarks.Params.from_config(
        {"landmarks": {"min_confidence": 0.3, "carry_stable": False, "stable_points": [28, 40]}}
    )
    assert params == landmarks.Params(0.3, False, (28, 40))
    assert landmarks.Params.from_config({}) == landmarks.Params()


def test_tracking_params_from_the_config():
    section = {"track": False, "min_track_confidence": 0.6, "max_track_px": 4, "track_weight": 1}
    params = landmarks.Params.from_config({"landmarks": section | {"turned_view_deg": 8}})
    assert (params.track, params.min_track_confidence) == (False, 0.6)
    assert (params.max_track_px, params.track_weight) == (4.0, 1.0)
    assert params.turned_view_deg == 8.0
    assert (
        landmarks.Params.from_config({"landmarks": {"turned_view_deg": None}}).turned_view_deg
        is None
    )


def test_an_unfolded_detection_is_a_warning(car, monkeypatch):
    """A detected take whose points the second pass moved towards the neutral's (the fit
    would have folded) says so in ``doubtful``, beside a low confidence's reason, and the
    stage hands the template to the second pass."""
    r = car
    data = {
        paths.range_image("car", "xyz"): r["xyz"],
        paths.range_image("car", "color"): r["color"],
    }
    found = landmarks.Landmarks(r["landmarks"], landmarks.DETECTED, np.full(68, 0.2), "d", "1")
    seen = {}

    def second_pass(found, take, grids, params, template=None):
        seen["template"] = template
        return found, {"landmarks_unfolded": 0.5}

    monkeypatch.setattr(landmarks, "settle", lambda *a: found)
    monkeypatch.setattr(landmarks, "second_pass", second_pass)
    take = Take("s1", "car", "viseme", "car", "neutral", data)
    part = landmarks.run("the template", take, landmarks.Params())
    assert seen["template"] == "the template"
    message = part.datasets[paths.landmark_info("car", "doubtful")]
    assert message.startswith("the detected landmarks are doubtful: median confidence 0.20")
    assert "; the detected landmarks would make the template fit leave the take out" in message
    assert "moved 50% of the way to the neutral's" in message
    assert part.attrs[paths.take("car")]["landmarks_unfolded"] == 0.5


def test_the_fold_test_follows_the_fit_params():
    config = {"landmarks": {"unfold": False}, "template": repo_config()["template"]}
    params = landmarks.Params.from_config(config)
    assert params.unfold is False and params.fit is None  # no test, no re-run on its keys
    on = landmarks.Params.from_config(config | {"landmarks": {}})
    full = fit.Params.from_config(config)
    assert (on.fit.fiducials, on.fit.rim_share) == (full.fiducials, full.rim_share)
    assert (on.fit.rules.levels, on.fit.rules.max_fold_fraction) == (
        full.rules.levels,
        full.rules.max_fold_fraction,
    )
    # the sampling rules do not reach the fold test: changing them changes no landmarks params
    other = config | {"template": config["template"] | {"sample_min_weight": 0.9}}
    assert landmarks.Params.from_config(other | {"landmarks": {}}) == on
    no_carry = config | {"landmarks": {"carry_stable": False}}
    assert landmarks.Params.from_config(no_carry).fit is None
    assert landmarks.Params.from_config({}).fit is None


def test_points_on_made_up_surface_are_lifted_from_the_measured_one():
    """The .xyz points lie on what the scan measured: a point in a hole the repair filled (or on
    a replaced spike) takes the nearest measured pixel, not the made-up surface (a mesh reader
    would refuse it more than 5 mm off the mesh)."""
    r = make_take("s1", "car", "viseme", "car", 3, {"width": 320, "height": 240, "focal_px": 725.0})
    xyz = np.array(r["xyz"], dtype=np.float64)
    tip = r["landmarks"][30]  # the nose tip, iBUG 31
    rows, cols = np.mgrid[: xyz.shape[0], : xyz.shape[1]]
    hole = np.hypot(cols - tip[0], rows - tip[1]) < 6.0
    filled = np.where(hole[..., None], xyz + [0.0, 0.0, 20.0], xyz)  # a made-up bump
    data = {
        paths.range_image("car", "xyz"): filled,
        paths.range_image("car", "color"): r["color"],
        paths.clicks("car"): r["landmarks"],
        paths.range_image("car", "filled"): hole,
    }
    take = Take("s1", "car", "viseme", "car", "neutral", data)
    lifted = landmarks.run(None, take, landmarks.Params()).files["xyz"]
    measured = xyz[~hole & np.isfinite(xyz).all(axis=2)]
    assert np.min(np.linalg.norm(measured - lifted[30], axis=1)) == 0.0  # a measured pixel
    without = dict(data)
    del without[paths.range_image("car", "filled")]
    take = Take("s1", "car", "viseme", "car", "neutral", without)
    bump = landmarks.run(None, take, landmarks.Params()).files["xyz"][30]
    # the made-up surface, had the mask not said so: the bump 20 mm off the measured nose
    from scan2morph.template.sample import sample_range

    true_tip = sample_range(xyz, tip[None], "car", 0.5)[0][0]
    np.testing.assert_allclose(bump, true_tip + [0.0, 0.0, 20.0], atol=0.5)


@pytest.mark.parametrize("source", ["clicked", "detected"])
def test_a_fit_refusing_detected_landmarks_says_they_were_detected(car, source):
    """Landmarks that fold the template: clicked ones are refused as before, detected ones with
    a word that the user gave none, and where the points are to correct and give back (the
    refusal used to read as about the user's clicks)."""
    points = np.array(car["landmarks"], dtype=float)
    points[[36, 45]] = points[[45, 36]]  # the outer eye corners swapped: the fit folds
    data = {
        paths.range_image("car", "xyz"): car["xyz"],
        paths.landmarks("car"): points,
        paths.landmark_info("car", "source"): source,
    }
    take = Take("s1", "car", "neutral", "neutral", "car", data)  # its own neutral
    with pytest.raises(InputError, match="fold") as refused:
        fit.run(build_template(), take, fit.Params.from_config(repo_config()))
    hint = "its landmarks were detected, not given: correct them in landmarks/car.pts"
    assert (hint in str(refused.value)) == (source == "detected"), refused.value


def test_a_doubtful_detection_beside_given_landmarks_says_its_error_is_in_the_motion(tmp_path):
    """A subject mixing given and detected landmarks: a doubtful detection's error is not in
    the given takes' points, so the warning no longer says it stays out of the motions (on the
    real head a clicked smile beside a detected neutral moved 25 times the skin's error of both
    detected)."""
    message = DOUBTFUL
    said = _said(tmp_path / "store.h5", *_doubtful_subject("c", "clicked"))
    mixed = (
        "; the subject mixes detected and given landmarks (given: c): this detection's error is "
        "not in theirs, so it is in the motion between them where no refinement follows the "
        "skin; give this take's landmarks too, or none for any take"
    )
    assert said["n"] == message + mixed
    assert said["s"].startswith(message + mixed + "; its refinement (by its texture) measured")
    assert "c" not in said


def test_a_refused_detection_carries_its_points_to_correct(car, tmp_path):
    """Detected points that a face check refuses (an outer eye corner where the scan has a
    hole): the take is left out, and the refusal carries the detection and its points on the
    surface, which the take's job writes for the user to correct and give back (it used to
    write a file with no points). The .pts with its note reads back as the points."""
    from scan2morph.io import read_pts, write_pts

    xyz = np.array(car["xyz"])
    rows, cols = np.mgrid[: xyz.shape[0], : xyz.shape[1]]
    x, y = car["landmarks"][45]
    xyz[(abs(cols - x) < 16) & (abs(rows - y) < 16)] = np.nan  # a hole over iBUG 46
    data = {paths.range_image("car", "xyz"): xyz, paths.range_image("car", "color"): car["color"]}
    take = Take("s1", "car", "neutral", "neutral", "car", data)
    with pytest.raises(landmarks.RefusedDetection, match="iBUG 46 .* lies where the range") as no:
        landmarks.run(None, take, landmarks.Params())
    refused = no.value
    assert isinstance(refused, InputError)
    assert refused.points.shape == (68, 2) and np.isfinite(refused.points).all()
    assert np.median(np.linalg.norm(refused.points - car["landmarks"], axis=1)) < 3.0
    assert refused.surface.shape == (68, 3) and np.isfinite(refused.surface).all()
    path = tmp_path / "car.pts"
    write_pts(path, refused.points, comment="detected landmarks refused (car left out): correct")
    assert path.read_text().startswith("# detected landmarks refused")
    np.testing.assert_allclose(read_pts(path), refused.points, atol=1e-4)


def test_the_take_job_writes_a_refused_detection_and_a_record_without_points(tmp_path):
    """The take job's files for a take left out at its landmarks: a refused detection's points
    (the .pts with a first line saying why, the .xyz as MeshLab opens it), which read back as
    landmark files; without points (no face found) the record alone, which says what it is."""
    import importlib.util
    from types import SimpleNamespace

    from scan2morph.io import read_pts
    from scan2morph.io.mesh_scan import read_landmarks3d
    from scan2morph.store.warnings import Failure
    from tests.support.workflow_api import REPO

    spec = importlib.util.spec_from_file_location("take_job", REPO / "workflow/scripts/take.py")
    job = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(job)
    rng = np.random.default_rng(5)
    refused = landmarks.RefusedDetection(
        InputError("s1/car", "iBUG 46 lies off"), rng.random((68, 2))
    )
    refused.surface = rng.random((68, 3)) * 100.0
    out = SimpleNamespace(pts=tmp_path / "car.pts", xyz=tmp_path / "car.xyz")
    j = SimpleNamespace(out=out, p=SimpleNamespace(row={"modality": "range"}))
    record = Failure("car", "landmarks", "s1/car: iBUG 46 lies off")
    job.write_left_out_landmarks(j, record, refused)
    assert out.pts.read_text().startswith("# detected landmarks refused (car left out at")
    np.testing.assert_allclose(read_pts(out.pts), refused.points, atol=1e-4)
    np.testing.assert_allclose(read_landmarks3d(out.xyz), refused.surface, rtol=1e-5)
    refused.surface[3] = np.nan  # a point off the data: the .xyz is the record, the .pts kept
    job.write_left_out_landmarks(j, record, refused)
    np.testing.assert_allclose(read_pts(out.pts), refused.points, atol=1e-4)
    with pytest.raises(InputError, match="the pipeline's record of a take left out"):
        read_landmarks3d(out.xyz)
    job.write_left_out_landmarks(j, record, None)
    with pytest.raises(InputError, match="the pipeline's record of a take left out"):
        read_pts(out.pts)


def test_a_doubtful_detection_beside_a_given_neutral_says_it_follows_the_neutral(tmp_path):
    """A detected take whose neutral's landmarks were given follows them through the skin (the
    second pass, all the way): the warning says so, not that its error is in the motion."""
    data, attrs = _doubtful_subject("v", "detected")
    data[paths.landmark_info("n", "source")] = "clicked"
    data[paths.landmark_info("n", "doubtful")] = ""
    untracked = _said(tmp_path / "store.h5", data, attrs)  # landmarks.track off: no following
    assert "the subject mixes detected and given landmarks (given: n)" in untracked["v"]
    attrs[paths.take("v")] = attrs[paths.take("v")] | {"landmarks_tracked": 30}
    said = _said(tmp_path / "store.h5", data, attrs)
    assert "n" not in said
    assert said["v"] == DOUBTFUL + (
        "; its neutral's landmarks were given: where the skin's texture correlates its points "
        "follow the neutral's, elsewhere this detection's error is in its motion (give this "
        "take's landmarks too, or none for any take)"
    )
    assert said["s"].endswith("there the take's own detection error is taken up")


def _misplaced_features(clicks: np.ndarray) -> np.ndarray:
    """The car's clicks (0.5 px off the truth) with the mouth too wide and low, the brows
    6 px (8 mm) too high and the jaw 12 px too low, as the detector puts a real face's."""
    start = clicks.copy()
    centre = start[48:].mean(axis=0)
    start[48:] = centre + (start[48:] - centre) * [1.3, 1.0] + [0.0, 3.0]
    start[17:27, 1] -= 6.0
    start[:17, 1] += 12.0
    return start


@pytest.mark.parametrize(
    ("confidence", "config", "lips", "brows", "chin"),
    [
        (0.2, {}, True, True, True),
        (0.9, {}, False, False, False),
        (0.2, {"lips_from_colour": False}, False, True, True),
        (0.2, {"brows_from_colour": False}, True, False, True),
        (0.2, {"chin_from_shape": False}, True, True, False),
    ],
)
def test_a_doubtful_detections_features_go_onto_the_face(
    car, monkeypatch, confidence, config, lips, brows, chin
):
    """A doubtful detection (median confidence below ``min_confidence``) has its mouth placed on
    the lips' colour edge (scan2morph.landmarks.fit_lips), its brows on the eyebrows' bands
    (scan2morph.landmarks.fit_brows) and its chin, with the jawline, on the face's outline
    (scan2morph.landmarks.fit_chin, from the points the other steps placed: its midline runs
    through the lips); a sure one keeps the detector's, and ``landmarks.lips_from_colour:
    false`` / ``brows_from_colour: false`` / ``chin_from_shape: false`` keep every detection's
    mouth / brows / jawline."""
    r = car
    data = {
        paths.range_image("car", "xyz"): r["xyz"],
        paths.range_image("car", "color"): r["color"],
    }
    start = _misplaced_features(r["landmarks"])
    found = landmarks.Landmarks(start, landmarks.DETECTED, np.full(68, confidence), "d", "1")
    monkeypatch.setattr(landmarks, "settle", lambda *a: found)
    take = Take("s1", "car", "viseme", "car", "car", data)  # its own neutral: no second pass
    params = landmarks.Params.from_config({"landmarks": config})
    part = landmarks.run(None, take, params)
    got = part.datasets[paths.landmarks("car")]
    attrs = part.attrs[paths.take("car")]
    np.testing.assert_array_equal(got[27:48], start[27:48])
    # the synthetic brow clicks lie 1 mm (0.7 px here) above the band's middle, where the fit
    # puts them, and carry 0.5 px of click noise
    features = (("lips", slice(48, 68), lips, 1.5), ("brows", slice(17, 27), brows, 2.0))
    for name, span, moves, bound in features:
        before = np.median(np.linalg.norm(start[span] - r["landmarks"][span], axis=1))
        after = np.median(np.linalg.norm(got[span] - r["landmarks"][span], axis=1))
        key = f"landmarks_{name}_moved_px"
        if moves:
            print(f"\ncar's {name} {before:.2f} -> {after:.2f} px from its clicks")
            assert after < bound < 3.0 < before
            assert attrs[key] > 2.0
        else:
            np.testing.assert_array_equal(got[span], start[span])
            assert key not in attrs
    np.testing.assert_array_equal(got[[0, 16]], start[[0, 16]])  # the jaw's ends, by the ears
    if chin:  # the library's own answer (tests/unit/test_chin.py measures it)
        placed = fit_chin(r["xyz"], np.concatenate([start[:17], got[17:]]))
        np.testing.assert_array_equal(got[:17], placed.points[:17])
        assert attrs["landmarks_chin_moved_px"] == placed.moved_px > 3.0
        # towards the clicks (the generator's chin lies 2-4 px inside the outline at 320 x 240)
        before, after = (np.linalg.norm(p[8] - r["landmarks"][8]) for p in (start, got))
        print(f"\ncar's chin {before:.2f} -> {after:.2f} px from its clicks")
        assert after < 5.0 < before
    else:
        np.testing.assert_array_equal(got[:17], start[:17])
        assert "landmarks_chin_moved_px" not in attrs


@pytest.mark.parametrize("placed", [True, False])
def test_a_doubtful_takes_features_are_placed_before_its_second_pass(car, monkeypatch, placed):
    """A doubtful take other than the neutral: the second pass starts from its mouth on the lips,
    its brows on the eyebrows and its chin on the face's outline (off: from the detector's
    points), ``landmark_detected`` keeps
    the detector's own points, and the attributes hold every step's."""
    r = car
    data = {
        paths.range_image("car", "xyz"): r["xyz"],
        paths.range_image("car", "color"): r["color"],
    }
    start = _misplaced_features(r["landmarks"])
    found = landmarks.Landmarks(start, landmarks.DETECTED, np.full(68, 0.2), "d", "1")
    seen = {}

    def second_pass(found, take, grids, params, template=None):
        seen["points"] = found.points.copy()
        return found, {"landmarks_tracked": 7}

    monkeypatch.setattr(landmarks, "settle", lambda *a: found)
    monkeypatch.setattr(landmarks, "second_pass", second_pass)
    take = Take("s1", "car", "viseme", "car", "neutral", data)
    config = {"lips_from_colour": placed, "brows_from_colour": placed, "chin_from_shape": placed}
    params = landmarks.Params.from_config({"landmarks": config})
    part = landmarks.run(None, take, params)
    np.testing.assert_array_equal(part.datasets[paths.landmark_detected("car")], start)
    attrs = part.attrs[paths.take("car")]
    assert attrs["landmarks_tracked"] == 7
    moved = np.linalg.norm(seen["points"] - start, axis=1)
    if placed:
        assert np.median(moved[48:]) == pytest.approx(attrs["landmarks_lips_moved_px"])
        assert np.median(moved[17:27]) == pytest.approx(attrs["landmarks_brows_moved_px"])
        assert attrs["landmarks_lips_moved_px"] > 2.0 and attrs["landmarks_brows_moved_px"] > 2.0
        assert moved[8] == pytest.approx(attrs["landmarks_chin_moved_px"]) and moved[8] > 3.0
        assert not moved[[0, 16]].any() and not moved[27:48].any()
    else:
        assert not moved.any()
        steps = {f"landmarks_{n}_moved_px" for n in ("lips", "brows", "chin")}
        assert not steps & set(attrs)
