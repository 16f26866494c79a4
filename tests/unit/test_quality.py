"""Quality gates: warnings from a store's records, takes left out of the models."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from scan2morph.stages import Subject
from scan2morph.stages.quality import (
    SHAPE_REFINED,
    TURNED,
    TURNED_EXAMPLE,
    Warning,
    aligned_takes,
    modelled,
    read_warnings,
    skipped_stages,
    subject_warnings,
    warning_datasets,
)
from scan2morph.store import paths, read_part, write_part

SETTINGS = {
    "include_failed_takes": False,
    "max_click_noise_px": 1.5,
    "min_valid_fraction": 0.5,
    "max_view_turn_deg": 15.0,
    "max_clipped_share": 0.25,
    "max_noise_mm": 0.25,
}


@pytest.fixture
def store(tmp_path):
    valid = np.ones(10, bool)
    sparse = valid.copy()
    sparse[:7] = False
    data = {
        paths.mesh("n", "valid"): valid,
        paths.mesh("car", "valid"): valid,
        paths.mesh("smile", "valid"): sparse,
        paths.align("n", "ok"): np.bool_(True),
        paths.align("car", "ok"): np.bool_(True),
        paths.align("smile", "ok"): np.bool_(False),
        paths.motion_noise("takes"): ["car", "eel"],
        paths.motion_noise("failed_draws"): np.array([3, 16]),
        paths.motion_noise("click_noise_measured_px"): np.float64(2.25),
    }
    attrs = {
        paths.take("car"): {"n_folded": 2},
        paths.align_group("smile"): {"problems": ["ICP did not converge (50 iterations)"]},
        paths.MOTION_NOISE: {"draws": 16},
        paths.SKIPPED: {"morph": "no viseme takes"},
    }
    path = tmp_path / "s.h5"
    write_part(path, data, attrs=attrs)
    return path


def test_every_gate_gives_one_line(store):
    with h5py.File(store) as h5:
        warnings = subject_warnings(h5, SETTINGS)
        assert skipped_stages(h5) == {"morph": "no viseme takes"}
    assert [str(w) for w in warnings] == [
        "[fit] car: 2 folded triangles in the fitted template",
        "[fit] smile: only 30% of the template has data",
        "[align] smile: ICP did not converge (50 iterations): left out of the models",
        "[motion_noise] car: 3 of 16 click-noise refits refused: its error bar is partial",
        "[motion_noise] eel: too few of its 16 click-noise refits fitted (or of its neutral's: "
        "the click noise is too large for the template; the motion_noise log says why): it has "
        "no error bar",
        "[motion_noise] the landmark clicks scatter by 2.25 px, above 1.5 px: the motion of "
        "small visemes is not to be trusted",
    ]
    kept = subject_warnings(h5py.File(store), SETTINGS | {"include_failed_takes": True})
    assert "kept in the models (quality.include_failed_takes)" in kept[2].message


def test_the_scatter_of_detected_landmarks_is_not_called_clicks(store):
    """Where some takes' landmarks were detected, the measured scatter is the detector's: the
    warning speaks of the landmark points, not of clicks."""
    with h5py.File(store, "a") as h5:
        h5.create_dataset(paths.landmark_info("car", "source"), data="detected")
        said = [str(w) for w in subject_warnings(h5, SETTINGS)]
    assert said[-1].startswith("[motion_noise] the landmark points scatter by 2.25 px")


def test_takes_refined_by_their_shape_are_one_warning(store):
    """Takes whose texture did not correlate with the neutral's, refined by the surface's shape
    (about three times the error of a texture-refined take): one warning naming them; a take
    refined by its texture or not refined gives none (it used to say nothing at all)."""
    with h5py.File(store, "a") as h5:
        for take, shape in (("car", True), ("smile", False)):
            h5.require_group(paths.refine_group(take)).attrs["shape_used"] = shape
        said = [w for w in subject_warnings(h5, SETTINGS) if w.stage == "refine"]
    assert [str(w) for w in said] == ["[refine] " + SHAPE_REFINED.format(takes="car")]
    assert said[0].message.startswith("car: refined by the surface's shape")


def test_a_take_seen_from_another_direction_than_its_neutral_is_a_warning(tmp_path):
    """The audit's silent garbage: the real head's smile turned 20 degrees from its neutral kept
    0.85 of its motion in error with landmark files (0.12 seen as the neutral is) and the report
    said nothing. A take seen from more than quality.max_view_turn_deg away from where its
    neutral was (the angle at the face between the two cameras once aligned; a tilt about the
    line to the camera turns none) is now a warning naming the turn; the neutral itself, a take
    within the limit, a take in its own frame seen from the neutral's place, and a take whose
    alignment failed its gate (its turn would be the failed alignment's) are not."""
    from tests.support.turned_grids import ball_grid, middle, yaw_about

    ball = ball_grid()
    middle = middle({paths.range_image("n", "xyz"): ball}, "n")
    tilt = np.eye(4)
    tilt[:2, :2] = [[np.cos(0.6), -np.sin(0.6)], [np.sin(0.6), np.cos(0.6)]]  # 34 degrees
    tilt[:3, 3] = middle - tilt[:3, :3] @ middle
    frame = yaw_about(40.0, np.array([50.0, 0.0, 0.0]))
    transforms = {
        "n": np.eye(4),
        "car": yaw_about(12.0, middle),
        "smile": yaw_about(-21.4, middle),
        "tilt": tilt,
        "own_frame": np.linalg.inv(frame),
        "failed": yaw_about(40.0, middle),
    }
    data = {paths.align(t, "transform"): m for t, m in transforms.items()}
    data |= {paths.align(t, "ok"): np.bool_(t != "failed") for t in transforms}
    data |= {paths.range_image(t, "xyz"): ball for t in transforms}
    data[paths.range_image("own_frame", "xyz")] = ball_grid(frame)
    attrs = {paths.take(t): {"kind": "neutral" if t == "n" else "expression"} for t in transforms}
    attrs[paths.align_group("failed")] = {"problems": ["ICP did not converge (50 iterations)"]}
    write_part(tmp_path / "s.h5", data, attrs=attrs)
    with h5py.File(tmp_path / "s.h5") as h5:
        said = [w for w in subject_warnings(h5, SETTINGS) if w.stage == "align"]
        assert [w.take for w in said] == ["failed", "smile"]
        assert said[0].message.startswith("ICP did not converge")
        assert said[1].message == TURNED.format(turn=21.4, example=TURNED_EXAMPLE)
        assert said[1].message.startswith("seen from 21 degrees away from where its neutral was")
        stricter = subject_warnings(h5, SETTINGS | {"max_view_turn_deg": 10.0})
        assert [w.take for w in stricter if "degrees away" in w.message] == ["car", "smile"]


def test_warnings_round_trip_through_the_store(store, tmp_path):
    warnings = [Warning("align", "smile", "bad"), Warning("motion_noise", "", "noisy")]
    write_part(tmp_path / "w.h5", warning_datasets(warnings))
    assert read_warnings(read_part(tmp_path / "w.h5")) == warnings
    with h5py.File(tmp_path / "w.h5") as h5:
        assert read_warnings(h5) == warnings
    write_part(tmp_path / "none.h5", warning_datasets([]))
    assert read_warnings(read_part(tmp_path / "none.h5")) == []
    assert read_warnings({}) == []  # a store from before format 1.2


def test_failed_alignments_are_left_out_of_the_models(store):
    data = read_part(store)
    assert aligned_takes(data, ["car", "smile"], include_failed=False) == ["car"]
    assert aligned_takes(data, ["car", "smile"], include_failed=True) == ["car", "smile"]
    subject = Subject("s", {"n": "neutral", "car": "viseme", "smile": "expression"}, {})
    motion = {paths.viseme("car", "model"): np.zeros((10, 3))}
    assert modelled(subject, motion).kinds == {"n": "neutral", "car": "viseme"}


def test_the_report_shows_warnings_and_skipped_stages_first(store):
    from scan2morph.report.html import _status_section
    from scan2morph.store.hdf5 import write_datasets

    with h5py.File(store) as h5:
        warnings = subject_warnings(h5, SETTINGS)
    write_datasets(store, warning_datasets(warnings))  # as the store stage does
    with h5py.File(store) as h5:
        html = _status_section(h5)
    assert html.startswith('<div class="warnings">') and "6 warnings" in html
    assert "ICP did not converge (50 iterations): left out of the models" in html
    assert "no viseme takes" in html  # the skipped stages' table


def test_a_scan_with_no_data_under_its_mouth_and_nose_points_is_a_warning(store):
    """The bad-input audit's F4: a smile whose scan lost its lower half (an occlusion, a cut
    scan) kept 68% of its template valid, above quality.min_valid_fraction, and its mouth's
    motion was filled in without a word. More than 8 of the 41 eye, nose and mouth points on no
    data is now a warning naming them; brows on unseen hair and a few points over an open
    mouth are not."""
    from scan2morph.stages.quality import MAX_UNMEASURED_POINTS, unmeasured_landmarks

    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(100, 220, 68), rng.uniform(40, 200, 68)])
    points[27:48, 1] = rng.uniform(60, 110, 21)  # nose bridge and eyes: upper half
    points[48:, 1] = rng.uniform(130, 170, 20)  # mouth: lower half
    xyz = np.ones((240, 320, 3))
    with h5py.File(store, "a") as h5:
        for take in ("car", "smile"):
            h5[paths.landmarks(take)] = points
        h5[paths.range_image("car", "xyz")] = xyz
        cut = xyz.copy()
        cut[120:] = np.nan  # the lower half lost
        cut[:, :2] = np.nan  # and a few points out of the image
        h5[paths.range_image("smile", "xyz")] = cut
        assert unmeasured_landmarks(h5, "car") == []
        off = unmeasured_landmarks(h5, "smile")
        warnings = [str(w) for w in subject_warnings(h5, SETTINGS) if "no data" in str(w)]
    assert off == list(range(49, 69)) and len(off) > MAX_UNMEASURED_POINTS
    assert warnings == [
        "[fit] smile: 20 of its 41 eye, nose and mouth landmarks (iBUG 49-68) lie where its scan "
        "has no data: the template there is filled in from the measured skin around it, not "
        "measured"
    ]


def test_a_colour_image_clipped_on_much_of_the_face_is_a_warning(tmp_path):
    """The audit's silent garbage: the real head's RGB-D smile with its images twice as bright
    (the face white: 99% of its pixels with a channel at 255) kept 0.56 of its motion in error
    and the report said nothing. A take whose colour image is clipped on more than
    quality.max_clipped_share of its face is now a warning naming the share. The face is the
    pixels with a surface point within the landmarks' hull: a white wall behind the head that a
    depth camera sees, or white hair, does not count, and a face clipped in front of a dark
    background is not diluted by it. A take clipped on less, a float image (no known top), a
    take without a colour image or without landmarks are no warning."""
    from scan2morph.evaluate import face_region
    from scan2morph.refine import clipped_share
    from scan2morph.stages.quality import CLIPPED, CLIPPED_EXAMPLE

    xyz = np.ones((60, 80, 3))  # every pixel has a surface point: the wall too
    color = np.full((60, 80, 3), 120, np.uint8)
    color[:, :20] = 255  # a white wall left of the face
    # 68 landmarks whose hull is the face's square, columns 30-69 and rows 10-49
    marks = np.random.default_rng(0).uniform([31, 11], [68, 48], (68, 2))
    marks[:4] = [[30.0, 10.0], [69.0, 10.0], [69.0, 49.0], [30.0, 49.0]]
    bright = color.copy()
    bright[10:22, 30:70, 1] = 255  # 12 of the face's 40 rows: 30%
    dim = color.copy()
    dim[10:18, 30:70] = 255  # 20%
    white = np.full((60, 80, 3), 10, np.uint8)  # a white face against a dark background
    white[10:50, 30:70] = 255
    takes = ("n", "bright", "dim", "white", "float", "none", "unmarked")
    data = {paths.range_image(t, "xyz"): xyz for t in takes}
    data |= {paths.landmarks(t): marks for t in takes if t != "unmarked"}
    data |= {paths.range_image(t, "color"): color for t in ("n", "unmarked")}
    data |= {paths.range_image("bright", "color"): bright, paths.range_image("dim", "color"): dim}
    data[paths.range_image("white", "color")] = white
    data[paths.range_image("float", "color")] = bright.astype(np.float32)
    data |= {paths.align(t, "ok"): np.bool_(True) for t in takes}
    attrs = {paths.take(t): {"kind": "expression"} for t in takes}
    write_part(tmp_path / "s.h5", data, attrs=attrs)
    face = face_region(np.isfinite(xyz).all(axis=-1), marks)
    assert clipped_share(color, face) == 0.0  # the white wall is not the face
    assert clipped_share(bright, face) == pytest.approx(0.3)
    assert clipped_share(dim[..., 0], face) == pytest.approx(0.2)  # a grey image
    assert clipped_share(white, face) == 1.0
    with h5py.File(tmp_path / "s.h5") as h5:
        said = [w for w in subject_warnings(h5, SETTINGS) if w.stage == "ingest"]
        assert [w.take for w in said] == ["bright", "white"]
        assert said[0].message == CLIPPED.format(share=30.0, example=CLIPPED_EXAMPLE)
        assert said[0].message.startswith(
            "the colour image is clipped (a channel at the top of its range) on 30.0% of the "
            "face: over-exposed"
        )
        stricter = subject_warnings(h5, SETTINGS | {"max_clipped_share": 0.1})
        assert [w.take for w in stricter if w.stage == "ingest"] == ["bright", "dim", "white"]


def test_a_take_noisier_than_the_limit_is_a_warning(tmp_path):
    """The audit's silent garbage: the real head's RGB-D smile seen from 1.2 m (2 mm per pixel,
    depth noise about 3 mm) kept 0.97 of its motion in error and said nothing. A take, or the
    neutral, whose surface the alignment measured noisier than quality.max_noise_mm is now a
    warning naming the noise (the neutral's from the first aligned take, once); takes within
    the limit and takes without an alignment record are not."""
    from scan2morph.stages.quality import NOISY, NOISY_EXAMPLE

    attrs = {paths.take(t): {"kind": "expression"} for t in ("car", "smile", "eel", "too")}
    attrs[paths.take("n")] = {"kind": "neutral"}
    attrs[paths.align_group("car")] = {"noise_take_mm": 0.12, "noise_neutral_mm": 0.4}
    attrs[paths.align_group("smile")] = {"noise_take_mm": 0.69, "noise_neutral_mm": 0.4}
    attrs[paths.align_group("eel")] = {"noise_take_mm": 0.25, "noise_neutral_mm": 0.4}
    data = {paths.align(t, "ok"): np.bool_(True) for t in ("n", "car", "smile", "eel", "too")}
    write_part(tmp_path / "s.h5", data, attrs=attrs)
    with h5py.File(tmp_path / "s.h5") as h5:
        said = [w for w in subject_warnings(h5, SETTINGS) if "noisy" in w.message]
        assert [(w.stage, w.take) for w in said] == [("align", "n"), ("align", "smile")]
        assert said[1].message == NOISY.format(noise=0.69, example=NOISY_EXAMPLE)
        assert said[1].message.startswith("its surface is noisy: 0.69 mm RMS")
        assert said[0].message.startswith("its surface is noisy: 0.40 mm RMS")
        laxer = subject_warnings(h5, SETTINGS | {"max_noise_mm": 0.5})
        assert [w.take for w in laxer if "noisy" in w.message] == ["smile"]
