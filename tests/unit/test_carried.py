"""A detected take's upper face carried from its neutral (scan2morph.refine.carried) and the
steep skin the refinement measured nothing on left to its neighbours (refine stage), on scenes
with a known answer."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from scan2morph.refine.carried import UPPER_FACE_BELOW, carried_map, in_upper_face, upper_face
from scan2morph.stages import Subject, Take, consensus, refine
from scan2morph.stages.take_mesh import MEASURED, carries_upper, steep_skin, view_turn
from scan2morph.store import paths
from scan2morph.template import build_template, fit_map
from tests.support.configs import repo_config
from tests.support.plane_take import FULL, HALF, plane_landmarks, plane_take, renamed
from tests.support.turned_grids import ball_grid, middle, yaw_about

#: A detector's error in the take's view: its upper-face points this far off, px.
OFF = np.array([6.0, -4.0])


@pytest.fixture(scope="module")
def template():
    return build_template()


def _upper_landmarks(template):
    """iBUG indices (0-based) of the points in the upper face."""
    numbers, base = template.fiducial_set("closed")
    return numbers[in_upper_face(template, base)] - 1


def test_the_upper_face_is_the_template_above_the_top_of_the_jaw_line(template):
    level = template.ibug_xy[np.array(UPPER_FACE_BELOW) - 1, 1].mean()
    upper = upper_face(template)
    assert len(upper) > 50
    assert (template.vertices[upper, 1] < level).all()
    # the brows and eyes are in it, the nose's tip and the mouth are not
    up = set(_upper_landmarks(template) + 1)
    fiducials = set(template.fiducial_set("closed")[0])
    assert fiducials & (set(range(18, 28)) | set(range(37, 49))) <= up
    assert len(up) >= 10 and not up & ({31, 34} | set(range(49, 69)))


def test_the_carried_map_places_the_upper_face_at_the_neutrals_skin_and_the_rest_by_the_take(
    template,
):
    """The take is the neutral shifted by (5, 3) px (its carry: the known answer); its own
    upper-face points err by OFF. The carried map puts the upper face where the carry takes the
    neutral's (to 1e-6 px: the spline interpolates), the lower face's fiducials at the take's
    own points; the take's plain spline puts the upper face OFF away."""
    shift = np.array([5.0, 3.0])
    neutral = plane_landmarks(template)
    take = neutral + shift
    up = _upper_landmarks(template)
    take[up] += OFF
    neutral_map = fit_map(template, neutral, "closed")
    mapped = carried_map(template, take, "closed", neutral_map, lambda px: px + shift)
    upper = template.vertices[upper_face(template)]
    np.testing.assert_allclose(mapped(upper), neutral_map(upper) + shift, atol=1e-6)
    numbers, base = template.fiducial_set("closed")
    below = ~in_upper_face(template, base)
    np.testing.assert_allclose(
        mapped(template.vertices[base[below]]), take[numbers[below] - 1], atol=1e-6
    )
    plain = fit_map(template, take, "closed")(upper) - (neutral_map(upper) + shift)
    assert np.median(np.linalg.norm(plain, axis=1)) > 0.8 * np.linalg.norm(OFF)
    # a carry that finds nothing (fewer than 3 points on the take's surface) gives no map
    nothing = lambda px: np.full_like(px, np.nan)  # noqa: E731
    assert carried_map(template, take, "closed", neutral_map, nothing) is None


def _planes(template, config, depth_slope=(0.05, -0.03), off=OFF, doubtful=("she",), size=HALF):
    """A neutral and a take ``she`` of the same textured plane, the skin's texture flat (nothing
    to correlate) above the eyes (the image's upper half); the take's upper-face landmarks ``off``
    px off;
    the takes ``doubtful`` detected with a doubtful detection, the others detected."""
    landmarks = plane_landmarks(template, size)
    moved = landmarks.copy()
    moved[_upper_landmarks(template)] += off
    data = renamed(plane_take(template, 21, config, depth_slope, size=size), "neutral")
    data |= renamed(plane_take(template, 21, config, depth_slope, moved, size), "she")
    for take in ("neutral", "she"):
        colour = data[paths.range_image(take, "color")].copy()
        colour[: size[0] // 2] = 150
        data[paths.range_image(take, "color")] = colour
        data[paths.landmark_info(take, "source")] = b"detected"
        data[paths.landmark_info(take, "doubtful")] = DOUBT.encode() if take in doubtful else b""
    return data


DOUBT = "the detected landmarks are doubtful: median confidence 0.05 below 0.5"


def _aligned(data, take: str, transform: np.ndarray) -> None:
    """The take aligned by ``transform`` (4, 4) instead of the identity: its transform and its
    aligned fit (the plane takes' fit is in the take's frame), as the align stage writes them."""
    from scan2morph.align import transform_points

    data[paths.align(take, "vertices")] = transform_points(
        transform, data[paths.align(take, "vertices")]
    )
    data[paths.align(take, "transform")] = transform


@pytest.mark.parametrize(
    ("source", "doubtful", "which", "carried"),
    [
        ("detected", ("she",), "doubtful", True),
        ("detected", ("neutral",), "doubtful", True),
        ("detected", (), "doubtful", False),
        ("clicked", (), "doubtful", False),
        ("clicked", ("neutral",), "doubtful", True),
        ("detected", (), "detected", True),
        ("clicked+detected jawline", (), "detected", False),
        ("clicked", (), "all", True),
        ("detected", ("she", "neutral"), "none", False),
    ],
)
def test_which_takes_are_carried(source, doubtful, which, carried):
    """``refine.carry_upper_face``: by default the takes whose detection, or their neutral's, is
    doubtful (the detector's confidence is low: the real head's 0.05 against the synthetic
    cohort's 0.44-0.88); or every detected take, every take, none."""
    data = {paths.landmark_info("she", "source"): source.encode()}
    data |= {paths.landmark_info(t, "doubtful"): DOUBT.encode() for t in doubtful}
    data |= {paths.landmark_info(t, "doubtful"): b"" for t in {"she", "neutral"} - set(doubtful)}
    assert carries_upper(data, ("she", "neutral"), which) is carried


@pytest.mark.parametrize("doubtful", [("she",), ("neutral",), ()])
def test_a_doubtful_takes_upper_face_starts_from_the_neutrals_skin(template, doubtful):
    """The plane did not move, so every skin point of the take is the neutral's; the take's
    landmarks above the eyes are OFF px off, and the skin there is plain (nothing for the
    refinement to correct it with). Carried (the take's or its neutral's detection doubtful),
    the upper face's points are the neutral's to a fraction of a pixel; not carried, they keep
    most of the landmarks' error."""
    config = repo_config()
    data = _planes(template, config, doubtful=doubtful, size=FULL)
    params = refine.Params.from_config(config)
    assert params.carry_upper_face == config["refine"]["carry_upper_face"] == "doubtful"
    part = refine.run(template, Take("x", "she", "viseme", "she", "neutral", data=data), params)
    fine_upper = in_upper_face(template, np.arange(len(template.vertices)))
    got = part.datasets[paths.refine("she", "points2d")][: len(template.vertices)][fine_upper]
    neutral = data[paths.mesh("neutral", "points2d")][: len(template.vertices)][fine_upper]
    off = np.linalg.norm(got - neutral, axis=1)
    print(f"\ndoubtful {doubtful}: upper face off the neutral's skin by {np.median(off):.2f} px")
    assert part.attrs[paths.refine_group("she")]["upper_carried"] is bool(doubtful)
    if doubtful:
        assert np.median(off) < 0.3 and off.max() < 1.0
    else:
        assert np.median(off) > 0.4 * np.linalg.norm(OFF)  # measured 3.33 of 7.2


def test_steep_skin_is_left_to_its_neighbours(template):
    """Planes 66 and 75 degrees to the image plane (a pixel is 1.6 and 2.6 mm of depth), the
    skin's texture plain above the eyes, where the refinement measures nothing. In a doubtful
    take a vertex measured nowhere on skin steeper than refine.max_unmeasured_slope_deg (60), or
    a measured one steeper than refine.max_measured_slope_deg (70), is invalid (the motion stage
    fills it from its neighbours'); the others stay valid. A take not carried but seen from more
    than refine.turned_view_deg (5) from its neutral's direction has the same limits. A limit of
    None, a plane seen face-on, or a take neither carried nor turned leave every vertex as the
    fit has it."""
    config = repo_config()
    params = refine.Params.from_config(config)
    assert (params.max_unmeasured_slope_deg, params.max_measured_slope_deg) == (60, 70)
    assert config["refine"]["max_measured_slope_deg"] == 70
    assert params.turned_view_deg == config["refine"]["turned_view_deg"] == 5.0
    results = {}
    for name, slope, limits, doubtful, turn in (
        ("66", (1.6, 0.0), (60.0, 70.0), ("she",), 0.0),
        ("75", (2.6, 0.0), (60.0, 70.0), ("she",), 0.0),
        ("75, measured unlimited", (2.6, 0.0), (60.0, None), ("she",), 0.0),
        ("75, not carried", (2.6, 0.0), (60.0, 70.0), (), 0.0),
        ("75, not carried, turned 8", (2.6, 0.0), (60.0, 70.0), (), 8.0),
        ("75, not carried, turned 3", (2.6, 0.0), (60.0, 70.0), (), 3.0),
        ("face-on", (0.05, -0.03), (60.0, 70.0), ("she",), 0.0),
    ):
        data = _planes(template, config, slope, off=np.zeros(2), doubtful=doubtful)
        _aligned(data, "she", yaw_about(turn, middle(data, "neutral")))
        take = Take("x", "she", "viseme", "she", "neutral", data=data)
        limited = replace(
            params, max_unmeasured_slope_deg=limits[0], max_measured_slope_deg=limits[1]
        )
        part = refine.run(template, take, limited)
        results[name] = (
            part.datasets[paths.refine("she", "valid")],
            part.datasets[paths.refine("she", "confidence")] >= MEASURED,
            part.datasets[paths.refine("she", "vertices")],
            data[paths.mesh("she", "valid")],
        )
    valid, measured, vertices, fit = results["66"]
    print(f"\n66 degrees: {np.mean(~valid & fit):.2f} of the vertices left to their neighbours")
    assert measured.mean() > 0.3 and (~measured & fit).mean() > 0.2 and fit.mean() > 0.9
    np.testing.assert_array_equal(valid, fit & measured)
    assert np.isnan(vertices[~valid]).all() and np.isfinite(vertices[valid]).all()
    valid, measured, _, fit = results["75"]
    assert measured.mean() > 0.3 and fit.mean() > 0.9 and not valid.any()
    valid, measured, _, fit = results["75, measured unlimited"]
    np.testing.assert_array_equal(valid, fit & measured)
    valid, _, _, fit = results["75, not carried, turned 8"]  # steeper than either limit
    assert fit.mean() > 0.9 and not valid.any()
    for name in ("75, not carried", "75, not carried, turned 3", "face-on"):
        valid, _, _, fit = results[name]
        np.testing.assert_array_equal(valid, fit)


@pytest.mark.parametrize(
    ("takes", "doubtful", "turn", "limit", "steep"),
    [
        (("she", "neutral"), (), 8.0, 5.0, True),
        (("she", "neutral"), (), 3.0, 5.0, False),
        (("she", "neutral"), (), 30.0, None, False),
        (("she", "neutral"), ("she",), 0.0, 5.0, True),
        (("she", "neutral"), ("she",), 0.0, None, True),
        (("neutral", "neutral"), (), 8.0, 5.0, False),
    ],
)
def test_which_takes_leave_their_steep_skin_to_their_neighbours(
    takes, doubtful, turn, limit, steep
):
    """The carried takes (a doubtful detection, by default), and the takes seen from more than
    ``refine.turned_view_deg`` away from where their neutral was (the head turned between them:
    the take's alignment turns it back); never the neutral for its turn. Each take's camera is
    found from its own grid: a take whose points come in another frame (a range scanner's own,
    a mesh take's) but was seen from the neutral's place is not turned."""
    data = {paths.landmark_info(t, "source"): b"detected" for t in ("she", "neutral")}
    data |= {
        paths.landmark_info(t, "doubtful"): DOUBT.encode() if t in doubtful else b""
        for t in ("she", "neutral")
    }
    data |= {paths.range_image(t, "xyz"): ball_grid() for t in ("she", "neutral")}
    data[paths.align(takes[0], "transform")] = yaw_about(turn, middle(data, "neutral"))
    params = replace(refine.Params.from_config(repo_config()), turned_view_deg=limit)
    assert steep_skin(data, takes, params, "x/she") is steep
    if takes[0] != takes[1]:
        assert view_turn(data, takes, "x/she") == pytest.approx(turn, abs=1e-9)
        # the same scan in a frame of its own, aligned by the inverse motion: not turned
        frame = yaw_about(35.0, np.array([100.0, 0.0, 0.0]))
        frame[:3, 3] += [20.0, -40.0, 90.0]
        data[paths.range_image(takes[0], "xyz")] = ball_grid(frame)
        data[paths.align(takes[0], "transform")] = np.linalg.inv(frame)
        assert view_turn(data, takes, "x/she") == pytest.approx(0.0, abs=0.05)


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [
        ("carry_upper_face", "clicked", r"refine\.carry_upper_face: expected one of .*doubtful"),
        ("max_unmeasured_slope_deg", 95, "max_unmeasured_slope_deg"),
        ("max_measured_slope_deg", 0, "max_measured_slope_deg"),
        ("max_measured_slope_deg", 90, "max_measured_slope_deg"),
        ("turned_view_deg", -1.0, "turned_view_deg"),
        ("turned_view_deg", 180.0, "turned_view_deg"),
    ],
)
def test_a_bad_setting_is_refused_naming_it(key, value, expected):
    from scan2morph.config_schema import validate_config
    from scan2morph.errors import InputError
    from tests.support.configs import REPO

    config = repo_config()
    config["refine"][key] = value
    with pytest.raises(InputError, match=expected):
        validate_config(config, REPO / "schemas" / "config.schema.yaml")
    if key == "carry_upper_face":  # the library checks its own argument too
        with pytest.raises(
            InputError, match="expected one of doubtful, detected, all, none, got 'clicked'"
        ):
            replace(refine.Params.from_config(repo_config()), carry_upper_face=value)
    if key == "turned_view_deg":
        with pytest.raises(InputError, match=r"turned_view_deg: expected degrees in \[0, 180\)"):
            replace(refine.Params.from_config(repo_config()), turned_view_deg=value)


def test_a_take_the_carry_cannot_place_keeps_its_own_points(template, caplog):
    """A doubtful take whose alignment failed its gate, or whose alignment carries the neutral off
    its surface (a metre away: nothing found), starts from its own points, says so in its
    attributes (``upper_carried``), and with nothing found warns."""
    config = repo_config()
    params = refine.Params.from_config(config)
    for what in ("failed gate", "nothing found"):
        data = _planes(template, config)
        if what == "failed gate":
            data[paths.align("she", "ok")] = np.bool_(False)
        else:
            far = np.eye(4)
            far[2, 3] = 1000.0
            _aligned(data, "she", far)
        with caplog.at_level("WARNING", logger="scan2morph"):
            part = refine.run(
                template, Take("x", "she", "viseme", "she", "neutral", data=data), params
            )
        assert part.attrs[paths.refine_group("she")]["upper_carried"] is False, what
        warned = "upper face not carried: no neutral point found" in caplog.text
        assert warned == (what == "nothing found"), (what, caplog.text)
        caplog.clear()


def test_the_takes_consensus_keeps_a_carried_takes_steep_skin_to_its_neighbours(
    template, monkeypatch
):
    """The consensus resamples the takes it moves: a carried take keeps its refinement's slope
    limits there (here the consensus moves nothing, so its valid vertices are the refinement's);
    with the carry off, the fit's rules alone."""
    config = repo_config()
    data = _planes(template, config, (1.6, 0.0), off=np.zeros(2))
    params = refine.Params.from_config(config)
    refined = refine.run(template, Take("x", "she", "viseme", "she", "neutral", data=data), params)
    takes = ("a", "b", "c")
    subject_data = {k: v for k, v in data.items() if "/takes/she/" not in k}
    she = {k: v for k, v in data.items() if "/takes/she/" in k} | refined.datasets
    for t in takes:
        subject_data |= renamed(she, t, "she")
        subject_data[paths.refine_group(t)] = {"shape_used": True}
        subject_data[paths.align(t, "ok")] = np.bool_(True)
    kinds = {"neutral": "neutral"} | dict.fromkeys(takes, "viseme")
    subject = Subject("x", kinds, {t: t for t in kinds})

    def still(grid, vertices, before, images, flow, rounds, share):
        keep = {"kept": True, "confident_share": 1.0, "median_correction_px": 0.0}
        return dict(before), {t: keep for t in before}

    monkeypatch.setattr(consensus, "take_consensus", still)
    refine_valid = refined.datasets[paths.refine("she", "valid")]
    fit_valid = data[paths.mesh("she", "valid")]
    assert (fit_valid & ~refine_valid).mean() > 0.2  # the steep skin left out
    for which, expected in (("doubtful", refine_valid), ("none", fit_valid)):
        cfg = repo_config()
        cfg["refine"]["carry_upper_face"] = which
        part = consensus.run(template, subject, subject_data, consensus.Params.from_config(cfg))
        for t in takes:
            np.testing.assert_array_equal(part.datasets[paths.consensus(t, "valid")], expected)
