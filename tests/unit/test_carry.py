"""Stable landmarks carried from the neutral onto a take, and the others tracked from it by image
correlation (scan2morph.align.carry), against the generator's exact landmarks."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from scan2morph.align.carry import carry_stable, track_points
from scan2morph.refine import grey
from scan2morph.refine.flow import measure_flow
from scan2morph.scan import DEFAULT_REPAIR, repair_range
from scan2morph.stages import fit as fit_stage
from scan2morph.stages import landmarks
from scan2morph.stages.part import Take
from scan2morph.store import paths
from scan2morph.synth.cohort import make_take
from tests.support.configs import repo_config

STABLE = (28, 37, 40, 43, 46)
IDX = np.asarray(STABLE) - 1


@pytest.fixture(scope="module")
def takes():
    """take -> (repaired xyz, true landmarks px, colour); ``truth``: take -> the generator's
    pose (model -> camera, (4, 4) mm) and 3D landmarks (camera frame, mm)."""
    out: dict = {"truth": {}}
    for take, kind, label in (("neutral", "neutral", "neutral"), ("car", "viseme", "car")):
        r = make_take("s1", label, kind, take, 3)
        xyz = repair_range(r["xyz"], dict(DEFAULT_REPAIR), source=take)[0]
        out[take] = (xyz, r["truth"]["landmarks2d"], r["color"])
        out["truth"][take] = (r["truth"]["pose"], r["truth"]["landmarks3d"])
    return out


def _true_turn(takes) -> float:
    """The angle at the face (the neutral's 3D landmarks' mean) between the car's and the
    neutral's camera centres in the head's model frame, from the generator's poses, degrees."""
    (pose_t, _), (pose_n, marks) = takes["truth"]["car"], takes["truth"]["neutral"]
    face = (marks.mean(axis=0) - pose_n[:3, 3]) @ pose_n[:3, :3]  # camera -> model frame
    a, b = (-(p[:3, :3].T @ p[:3, 3]) - face for p in (pose_t, pose_n))
    return float(np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b))))


def test_noisy_stable_points_are_carried_onto_the_true_ones(takes):
    (xyz_n, true_n, _), (xyz_t, true_t, _) = takes["neutral"], takes["car"]
    rng = np.random.default_rng(0)
    noisy = true_t + rng.normal(0.0, 2.0, size=true_t.shape)
    got = carry_stable(xyz_t, noisy, xyz_n, true_n, STABLE, "s1/car")
    err_before = np.linalg.norm(noisy[IDX] - true_t[IDX], axis=1)
    err_after = np.linalg.norm(got.points[IDX] - true_t[IDX], axis=1)
    print(
        f"\nstable points off the truth: before {err_before.round(2)}, after {err_after.round(2)}"
    )
    assert got.carried.all()
    assert err_after.max() < 0.5 and np.median(err_after) < 0.3
    # the other points are left as they were
    others = np.setdiff1d(np.arange(68), IDX)
    np.testing.assert_array_equal(got.points[others], noisy[others])
    np.testing.assert_allclose(got.shift_px, err_before, atol=0.6)


def test_the_surface_icp_undoes_a_known_rigid_motion_the_same_every_time(takes):
    """The take is the neutral's surface moved by a known rigid motion (about 1 degree and 3 mm);
    started 0.3 degrees and 1.5 mm off the answer, the ICP returns the motion's inverse (take ->
    neutral) to 0.01 mm at the face, and the same bits when run again (its sums run in a fixed
    order: open3d's parallel ones gave other last digits from call to call)."""
    from scipy.spatial.transform import Rotation

    from scan2morph.align.carry import _surface_icp
    from scan2morph.align.rigid import invert, transform_points

    xyz_n, true_n, _ = takes["neutral"]
    move = np.eye(4)
    move[:3, :3] = Rotation.from_euler("xyz", [0.6, -0.7, 0.4], degrees=True).as_matrix()
    move[:3, 3] = [2.0, -1.5, 1.0]
    xyz_t = transform_points(move, xyz_n.reshape(-1, 3)).reshape(xyz_n.shape)
    rows, cols = np.rint(true_n[IDX, 1]).astype(int), np.rint(true_n[IDX, 0]).astype(int)
    centres = transform_points(move, xyz_n[rows, cols])
    assert np.isfinite(centres).all()
    start = np.eye(4)
    start[:3, :3] = Rotation.from_euler("y", 0.3, degrees=True).as_matrix()
    start[:3, 3] = [0.0, 1.5, 0.0]
    start = start @ invert(move)
    pose = _surface_icp(xyz_t, xyz_n, centres, start)
    face = xyz_n[np.isfinite(xyz_n).all(axis=2)]
    off = np.linalg.norm(transform_points(pose @ move, face) - face, axis=1)
    started = np.linalg.norm(transform_points(start @ move, face) - face, axis=1)
    print(f"\nat the face: {np.median(started):.2f} mm off at the start, {off.max():.5f} mm after")
    assert np.median(started) > 1.0 and off.max() < 0.01
    np.testing.assert_array_equal(_surface_icp(xyz_t, xyz_n, centres, start), pose)


def test_a_neutral_error_is_carried_as_it_is(takes):
    """The neutral's own error moves every take's stable points with it: they agree."""
    (xyz_n, true_n, _), (xyz_t, true_t, _) = takes["neutral"], takes["car"]
    off = true_n.copy()
    off[IDX] += np.array([1.5, -1.0])
    got = carry_stable(xyz_t, true_t, xyz_n, off, STABLE, "s1/car")
    shift = got.points[IDX] - true_t[IDX]
    assert np.abs(shift - shift.mean(axis=0)).max() < 0.5  # one rigid shift, ...
    assert 1.0 < np.linalg.norm(shift.mean(axis=0)) < 2.5  # ... about the neutral's


def test_too_few_stable_points_with_data_leaves_the_take_as_it_is(takes):
    (xyz_n, true_n, _), (xyz_t, true_t, _) = takes["neutral"], takes["car"]
    far = true_t.copy()
    far[IDX] = -50.0  # off the grid
    got = carry_stable(xyz_t, far, xyz_n, true_n, STABLE, "s1/car")
    assert not got.carried.any()
    np.testing.assert_array_equal(got.points, far)


#: The points on skin that moves with the mouth and the jaw (iBUG 1-based): not carried.
MOVING = np.setdiff1d(np.arange(68), IDX)


def test_the_neutral_points_are_tracked_onto_the_take_by_the_skin_texture(takes):
    """From the neutral's true points, the correlation finds the take's true points on the
    moving skin (the mouth opens for *car*), where the rigid prediction alone is off."""
    (xyz_n, true_n, color_n), (xyz_t, true_t, color_t) = takes["neutral"], takes["car"]
    carried = carry_stable(xyz_t, true_t, xyz_n, true_n, STABLE, "s1/car")
    got = track_points(
        (xyz_t, grey(color_t)),
        (xyz_n, grey(color_n)),
        true_n,
        carried.transform,
        partial(measure_flow, sigma=3.0, noise=2.0),
        "s1/car",
    )
    sure = got.confidence >= 0.3
    err = np.linalg.norm(got.points - true_t, axis=1)
    rigid = true_n @ got.affine[:, :2].T + got.affine[:, 2]
    err_rigid = np.linalg.norm(rigid - true_t, axis=1)
    print(
        f"\ntracked {sure.sum()} points: median {np.median(err[sure]):.2f} px, "
        f"rigid prediction {np.median(err_rigid[sure]):.2f} px"
    )
    assert sure.sum() >= 25
    assert np.median(err[sure]) < 0.5 and np.percentile(err[sure], 90) < 1.2
    # the mouth moved: the rigid prediction alone does not find it
    mouth = sure & (np.arange(68) >= 48)
    assert mouth.sum() >= 5 and np.median(err_rigid[mouth]) > 2 * np.median(err[mouth])
    # low confidence where the texture does not pin a point (the jawline's outline)
    assert np.median(got.confidence[:17]) < np.median(got.confidence[17:])


def _neutral(takes, color_n=None, given=False) -> dict:
    """The neutral's parts as a take's second pass reads them: its true points, detected (a
    confidence of 1 each) or, with ``given``, clicked (no confidence)."""
    xyz_n, true_n, color = takes["neutral"]
    data = {
        paths.range_image("neutral", "xyz"): xyz_n,
        paths.range_image("neutral", "color"): color if color_n is None else color_n,
        paths.landmarks("neutral"): true_n,
    }
    return data if given else data | {paths.landmark_confidence("neutral"): np.ones(68)}


def _second_pass(takes, params, as_grey=False, given=False, off_px=2.0, confidence=0.8):
    """The take's second pass, its points detected ``off_px`` off the truth (each axis) with
    ``confidence`` each (0.8: trusted, not doubtful at the default ``min_confidence`` 0.5)."""
    color_n, (xyz_t, true_t, color_t) = takes["neutral"][2], takes["car"]
    if as_grey:  # a geometry-only or stereo scan's grey image
        color_n, color_t = (np.rint(grey(c)).astype(np.uint8) for c in (color_n, color_t))
    data = _neutral(takes, color_n, given)
    noisy = true_t + np.random.default_rng(1).normal(0.0, off_px, size=true_t.shape)
    found = landmarks.Landmarks(noisy, landmarks.DETECTED, np.full(68, confidence), "d", "1")
    take = Take("s1", "car", "viseme", "car", "neutral", data)
    got, attrs = landmarks.second_pass(found, take, (xyz_t, color_t), params)
    return got, attrs, noisy, true_t


def test_the_second_pass_takes_the_moving_points_halfway_to_the_tracked_ones(takes):
    """A detection 2 px off (each axis): with the neutral's true points, the tracked share of
    each confidently tracked point removes that share of its error; without tracking the moving
    points stay where the detector put them."""
    got, attrs, noisy, true_t = _second_pass(takes, landmarks.Params(track_weight=0.5))
    moved = np.any(got.points != noisy, axis=1)
    moved[IDX] = False
    assert attrs["landmarks_tracked"] == moved.sum() >= 20
    before = np.linalg.norm(noisy - true_t, axis=1)[moved]
    after = np.linalg.norm(got.points - true_t, axis=1)[moved]
    print(f"\nmoving points: before {np.median(before):.2f} px, after {np.median(after):.2f} px")
    assert np.median(after) < 0.6 * np.median(before)
    # the tracked points' confidence: half the take's (0.8), half the neutral's (1)
    np.testing.assert_allclose(got.confidence[moved], 0.9)
    full, _, _, _ = _second_pass(takes, landmarks.Params(track_weight=1.0))
    assert np.median(np.linalg.norm(full.points - true_t, axis=1)[moved]) < 0.5
    off, attrs_off, _, _ = _second_pass(takes, landmarks.Params(track=False))
    assert "landmarks_tracked" not in attrs_off
    np.testing.assert_array_equal(off.points[MOVING], noisy[MOVING])


def _assert_followed_the_whole_way(got, attrs, noisy, true_t):
    """At least 20 moving points tracked, each onto the truth (the neutral's true points
    followed through the skin: median under 0.6 px), with the neutral's confidence (1)."""
    moved = np.any(got.points != noisy, axis=1)
    moved[IDX] = False
    assert attrs["landmarks_tracked"] == moved.sum() >= 20
    after = np.linalg.norm(got.points - true_t, axis=1)[moved]
    print(f"\ntracked {moved.sum()} points: median {np.median(after):.2f} px off the truth")
    assert np.median(after) < 0.6
    np.testing.assert_allclose(got.confidence[moved], 1.0)


def test_a_neutral_with_given_landmarks_is_followed_the_whole_way(takes):
    """The neutral's landmarks given (clicked), the take's detected 15 px off (a face unlike
    the detector's training faces, whose error a clicked neutral does not share): each
    confidently tracked point goes the whole way to where the neutral's skin went, however far
    from the detection (halfway and within max_track_px, a detection this far off kept its
    error: on the real head a clicked neutral with a detected smile moved 0.49 of the skin's
    motion in error, 0.085 this way)."""
    params = landmarks.Params(track_weight=0.5, max_track_px=6.0)
    got, attrs, noisy, true_t = _second_pass(takes, params, given=True, off_px=15.0)
    _assert_followed_the_whole_way(got, attrs, noisy, true_t)  # a clicked one's confidence: 1
    detected, attrs_d, _, _ = _second_pass(takes, params, off_px=15.0)  # a detected neutral
    assert attrs_d.get("landmarks_tracked", 0) < attrs["landmarks_tracked"] / 2


def test_a_doubtful_detection_seen_turned_is_followed_the_whole_way(takes):
    """The take's detection doubtful (median confidence 0.1, below ``min_confidence`` 0.5) and
    8 px off each axis (a real face's, for the synthetic-trained detector), the neutral's
    detected, the take seen turned from the neutral by more than ``turned_view_deg``: each
    confidently tracked point goes the whole way to where the neutral's skin went, as beside a
    clicked neutral (the neutral's error, which the tracking carries, cancels in the take's
    motion; a doubtful detection's own, from another view, does not: on the real head, whose
    detections are all doubtful, a smile turned 8 degrees from its neutral moved 0.69 of the
    skin's motion in error halfway within 6 px, 0.41 this way). The generator saw the car
    about 3.3 degrees turned from the neutral: the measured turn is checked against its poses;
    a limit of 2 degrees counts the take as turned, 5 does not, nor does the default (None:
    never), and the same
    points detected with confidence (0.8) stay within ``max_track_px`` of the detection."""
    turned = landmarks.Params(track_weight=0.5, max_track_px=6.0, turned_view_deg=2.0)
    got, attrs, noisy, true_t = _second_pass(takes, turned, off_px=8.0, confidence=0.1)
    truth = _true_turn(takes)
    print(f"\nview turn {attrs['landmarks_view_turn_deg']:.2f} degrees, true {truth:.2f}")
    assert 2.0 < truth < 5.0
    assert attrs["landmarks_view_turn_deg"] == pytest.approx(truth, abs=0.3)
    _assert_followed_the_whole_way(got, attrs, noisy, true_t)  # the neutral's confidence: 1
    near = _second_pass(takes, turned, off_px=8.0, confidence=0.8)[1]["landmarks_tracked"]
    assert near < attrs["landmarks_tracked"] / 2
    assert landmarks.Params().turned_view_deg is None  # the default: never
    for limit in (5.0, None):  # the take is turned less than 5 degrees
        params = landmarks.Params(track_weight=0.5, max_track_px=6.0, turned_view_deg=limit)
        unturned = _second_pass(takes, params, off_px=8.0, confidence=0.1)[1]
        assert unturned["landmarks_tracked"] == near


def _own_frame(xyz: np.ndarray) -> np.ndarray:
    """A range image's points in a frame of their own: turned 70 degrees about a slanted axis
    and moved 1 m (scanner XYZ may come in any right-handed frame)."""
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    a = np.radians(70.0)
    rotation = np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k
    return xyz @ rotation.T + np.array([300.0, -150.0, 900.0])


def test_the_view_turn_does_not_depend_on_the_take_s_frame(takes):
    """The take's points in a frame of their own: its camera (found from its grid) and the
    stable points' alignment move with them, and the turn stays the generator's. The synthetic
    cameras both stand at their frames' origin, where a transform taken the wrong way round
    (neutral -> take) gives nearly the same angle; here it gives over 100 degrees."""
    xyz_t, true_t, color_t = takes["car"]
    data = _neutral(takes)
    noisy = true_t + np.random.default_rng(1).normal(0.0, 8.0, size=true_t.shape)
    found = landmarks.Landmarks(noisy, landmarks.DETECTED, np.full(68, 0.1), "d", "1")
    take = Take("s1", "car", "viseme", "car", "neutral", data)
    params = landmarks.Params(track=False, unfold=False)
    turns = [
        landmarks.second_pass(found, take, (xyz, color_t), params)[1]["landmarks_view_turn_deg"]
        for xyz in (xyz_t, _own_frame(xyz_t))
    ]
    print(f"\nview turn {turns[0]:.3f} degrees, in a frame of its own {turns[1]:.3f}")
    assert turns[1] == pytest.approx(turns[0], abs=0.05)
    assert turns[0] == pytest.approx(_true_turn(takes), abs=0.3)


def test_a_take_with_two_stable_points_not_carried_still_has_its_turn(takes):
    """The take's scan has no data at two of its stable points (the left eye's corners): the
    alignment rests on the other three and does not carry those two; three carried points
    still measure the view (the real head turned 12 degrees loses an inner eye corner behind
    the nose), so the turn is the generator's."""
    xyz_t, true_t, color_t = takes["car"]
    rows, cols = np.mgrid[: xyz_t.shape[0], : xyz_t.shape[1]]
    holed = xyz_t.copy()
    for x, y in true_t[[36, 39]]:
        holed[(cols - x) ** 2 + (rows - y) ** 2 < 8.0**2] = np.nan
    noisy = true_t + np.random.default_rng(1).normal(0.0, 2.0, size=true_t.shape)
    found = landmarks.Landmarks(noisy, landmarks.DETECTED, np.full(68, 0.1), "d", "1")
    take = Take("s1", "car", "viseme", "car", "neutral", _neutral(takes))
    attrs = landmarks.second_pass(found, take, (holed, color_t), landmarks.Params())[1]
    print(f"\ncarried px {attrs['landmarks_carried_px']}")
    assert np.isnan(attrs["landmarks_carried_px"]).sum() == 2
    assert attrs["landmarks_view_turn_deg"] == pytest.approx(_true_turn(takes), abs=0.3)


def test_a_take_whose_stable_points_were_not_carried_has_no_turn(takes):
    """A detection 15 px off each axis: the alignment carries fewer than three stable points,
    its transform is no measure of the view, and the take is not counted as turned (NaN):
    tracked as a confident detection is, halfway within ``max_track_px``."""
    params = landmarks.Params(track_weight=0.5, max_track_px=6.0, turned_view_deg=0.0)
    got, attrs, _, _ = _second_pass(takes, params, off_px=15.0, confidence=0.1)
    assert np.isnan(attrs["landmarks_carried_px"]).sum() >= 3
    assert np.isnan(attrs["landmarks_view_turn_deg"])
    sure, attrs_sure, _, _ = _second_pass(takes, params, off_px=15.0, confidence=0.8)
    assert attrs.get("landmarks_tracked", 0) == attrs_sure.get("landmarks_tracked", 0)
    np.testing.assert_array_equal(got.points, sure.points)


def test_the_second_pass_tracks_on_grey_images(takes):
    """Grey (H, W) images are tracked like colour ones."""
    got, attrs, noisy, true_t = _second_pass(takes, landmarks.Params(), as_grey=True)
    moved = np.any(got.points != noisy, axis=1)
    moved[IDX] = False
    assert attrs["landmarks_tracked"] >= 20
    before = np.linalg.norm(noisy - true_t, axis=1)[moved]
    after = np.linalg.norm(got.points - true_t, axis=1)[moved]
    assert np.median(after) < 0.6 * np.median(before)


def _detected(takes, seed: int, template=None, params=None):
    """The car take's second pass from a detection 8 px off (each axis, seeded) with a
    confidence of 0.8 each (not doubtful: tracked halfway within 6 px), the neutral's points its
    truth: the points, the attributes and the detection after the pass alone."""
    xyz_t, true_t, color_t = takes["car"]
    data = _neutral(takes)
    noisy = true_t + np.random.default_rng(seed).normal(0.0, 8.0, size=true_t.shape)
    found = landmarks.Landmarks(noisy, landmarks.DETECTED, np.full(68, 0.8), "d", "1")
    take = Take("s1", "car", "viseme", "car", "neutral", data)
    params = params or landmarks.Params.from_config(repo_config())
    return landmarks.second_pass(found, take, (xyz_t, color_t), params, template)


def test_a_detection_that_folds_the_fit_goes_towards_the_neutrals_points_carried_rigidly(
    takes, monkeypatch
):
    """A detection 8 px off (a real face's, for the synthetic-trained detector) that folds the
    car take's template fit after the second pass: without the fold test the fit leaves the
    take out; with it the points go to the neutral's carried rigidly (the neutral's true
    points, here), and the real fit (:func:`fit_take`, not the test's own
    :func:`fit_folds`) then takes them, nearer the truth than before."""
    from scan2morph.align.carry import carry_points
    from scan2morph.errors import InputError
    from scan2morph.template import build_template, fit_take

    template = build_template()
    fit_params = fit_stage.Params.from_config(repo_config())
    (xyz_n, true_n, _), (xyz_t, true_t, _) = takes["neutral"], takes["car"]
    folding, attrs_off = _detected(takes, 2)
    assert "landmarks_unfolded" not in attrs_off
    # the fit stage's own fit: its rim placed from the neutral's points
    rim = fit_params.rim(
        Take("s1", "car", "viseme", "car", "neutral", {paths.landmarks("neutral"): true_n})
    )
    assert rim is not None
    with pytest.raises(InputError, match="landmarks fold the template"):
        fit_take(template, folding.points, xyz_t, None, "open", fit_params.rules, "s1/car", rim)
    got, attrs = _detected(takes, 2, template)
    share = attrs["landmarks_unfolded"]
    assert share == landmarks.UNFOLD_STEPS[0]
    mesh = fit_take(template, got.points, xyz_t, None, "open", fit_params.rules, "s1/car", rim)
    assert mesh["valid"].mean() > 0.9
    # each point on its way from where the second pass put it to the neutral's carried place
    noisy = true_t + np.random.default_rng(2).normal(0.0, 8.0, size=true_t.shape)
    transform = carry_stable(xyz_t, noisy, xyz_n, true_n, STABLE, "s1/car").transform
    carried = carry_points(xyz_t, xyz_n, true_n, transform)
    found = np.isfinite(carried).all(axis=1)
    assert found.all()
    np.testing.assert_allclose(
        got.points[found], (1 - share) * folding.points[found] + share * carried[found]
    )
    np.testing.assert_array_equal(got.points[~found], folding.points[~found])
    # a moved point's confidence: the share's of the neutral's (clicked: 1), as tracking does
    moved = np.any(got.points != folding.points, axis=1)
    assert moved.sum() > 30
    np.testing.assert_allclose(
        got.confidence[moved], share + (1 - share) * folding.confidence[moved]
    )
    before = np.median(np.linalg.norm(folding.points - true_t, axis=1))
    after = np.median(np.linalg.norm(got.points - true_t, axis=1))
    print(f"\nunfolded {share:.0%}: median error {before:.2f} -> {after:.2f} px")
    assert after < before
    # part of the way (the steps' first share folds no more here): each moved point and its
    # confidence a blend of the detection's (0.4, or 0.7 where tracking blended it) and the
    # neutral's (1), not either alone
    monkeypatch.setattr(landmarks, "UNFOLD_STEPS", (0.5,))
    half, attrs = _detected(takes, 2, template)
    assert attrs["landmarks_unfolded"] == 0.5
    np.testing.assert_allclose(
        half.points[found], 0.5 * folding.points[found] + 0.5 * carried[found]
    )
    moved = np.any(half.points != folding.points, axis=1)
    np.testing.assert_allclose(half.confidence[moved], 0.5 + 0.5 * folding.confidence[moved])
    assert (folding.confidence[moved] < half.confidence[moved]).all()
    assert (half.confidence[moved] < 1.0).all()


def test_a_detection_that_does_not_fold_is_left_as_it_is(takes):
    """Seed 0's detection (as far off) does not fold the fit after the pass: the fold test
    changes nothing; ``unfold: false`` switches the test off."""
    from scan2morph.template import build_template

    template = build_template()
    plain, attrs_plain = _detected(takes, 0)
    tested, attrs_tested = _detected(takes, 0, template)
    np.testing.assert_array_equal(tested.points, plain.points)
    np.testing.assert_equal(attrs_tested, attrs_plain)  # NaN shifts: points not carried
    off = landmarks.Params.from_config(repo_config() | {"landmarks": {"unfold": False}})
    assert off.unfold is False and off.fit is None
    folding, attrs_off = _detected(takes, 2, template, off)
    assert "landmarks_unfolded" not in attrs_off
