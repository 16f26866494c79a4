"""Tests of scan2morph.landmarks' training and model file (apart from tests/unit/test_landmarks.py
so that a parallel run (pytest-xdist, ``--dist loadscope``) trains on another worker than the
one simulating the detector's held-out takes)."""

from __future__ import annotations

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.landmarks.cascade import PATTERN, fit_stage, load, pattern, ridge_path, run, save
from scan2morph.landmarks.train import DEFAULTS, _fit_local, train

#: A tiny training: one range take, two local stages, two starts, one stretched copy.
TINY = {
    "subjects": 1,
    "takes": 1,
    "mesh_subjects": 0,
    "stereo_subjects": 0,
    "brow_takes": 0,
    "radii_mm": [6.0, 3.0],
    "starts": 2,
    "stretched": 1,
}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A training on :data:`TINY` (seed 5) and the cache folder it kept its simulated takes in
    (the module's other trainings of seed 5 read them from there)."""
    cache = tmp_path_factory.mktemp("samples")
    return train(5, TINY, cache=cache), cache


def test_training_is_deterministic(tiny):
    """Two trainings with the same seed on a tiny set give identical weights, the second from
    the simulated takes the first kept in its cache (their simulation's determinism is
    test_synth's); another seed gives other weights (seed 1: its face ``train000`` is the one
    :func:`test_extra_subjects_leave_the_committed_takes_as_they_were` simulates, its head built
    once in a worker)."""
    config = TINY
    (a, cache), b = tiny, train(5, config, cache=tiny[1])
    assert [p.name for p in cache.iterdir()] == ["samples-5-1x1.npz"]
    c = train(1, config)
    for s, t in zip(a.stages, b.stages, strict=True):
        np.testing.assert_array_equal(s.weights, t.weights)
        np.testing.assert_array_equal(s.bias, t.bias)
    np.testing.assert_array_equal(a.init, b.init)
    assert not np.array_equal(a.stages[0].weights, c.stages[0].weights)
    assert a.meta["seed"] == 5 and a.meta["config"]["takes"] == 1


def test_stereo_training_take_has_its_truth_on_its_grid(monkeypatch):
    """A simulated stereo training take, reconstructed as the ingest stage does: its truth lies
    on the left camera's raw grid (where the reconstruction's points and the colour are): the
    nose tip found on the reconstructed surface is within 1.5 px of the truth's point 31, and the
    reconstruction covers most of the inner face's truth points. The trainer's rig on a 320 x 240
    sensor with half its focal length (the face fills the same share of the image; the grids'
    mapping does not depend on their size): measured 0.78 px and 0.98 (at 640 x 480: 1.66 px,
    i.e. 0.83 at this scale, and 0.86), in 2.7 CPU-s instead of 6.1."""
    from scan2morph.landmarks.data import make_stereo_samples
    from scan2morph.landmarks.face import find_face
    from scan2morph.synth import stereo
    from scan2morph.template.sample import sample_range

    full = stereo.make_stereo_take

    def half(subject, label, kind, take, seed, params, *rest):
        small = dict(params) | {"width": 320, "height": 240, "focal_px": params["focal_px"] / 2}
        return full(subject, label, kind, take, seed, small, *rest)

    monkeypatch.setattr(stereo, "make_stereo_take", half)
    (s,) = make_stereo_samples(5, 1, 1)
    assert s.name.startswith("stereo000/t00/") and s.name.endswith("/stereo")
    assert s.color.shape == s.xyz.shape == (240, 320, 3) and s.truth.shape == (68, 2)
    nose = find_face(s.xyz, s.name).nose_px
    print(f"nose tip found {nose}, truth {s.truth[30]}")
    assert np.linalg.norm(nose - s.truth[30]) < 1.5
    inner = sample_range(s.xyz.astype(float), s.truth[17:], s.name, 0.5)[0]
    assert np.isfinite(inner).all(axis=1).mean() > 0.75  # eyes, nostrils: holes


def test_default_recipe_simulates_the_committed_subjects_and_extra_ones_only_when_asked(
    monkeypatch,
):
    """The trainer's takes at the committed settings are those of the committed subjects (40
    range/RGB-D ``train`` identities x 8 takes, 10 mesh x 4, 15 stereo x 4, and 2 brow takes of
    each range/RGB-D identity, grouped with it), nothing else; ``extra_subjects`` adds exactly
    that many ``wide`` identities' takes, drawn with the requested shares, the committed calls
    unchanged."""
    from scan2morph.landmarks import data
    from scan2morph.landmarks import train as train_mod

    calls, conventions = [], set()

    def fake(kind):
        def make(seed, n, k, extra=None, convention="synth", brows=False):
            calls.append((kind if not brows else "brows", seed, n, k, extra))
            conventions.add(convention)
            prefix = {"range": "train" if extra is None else "wide"}.get(kind, kind)
            first = "b" if brows else "t"
            return [f"{prefix}{i:03d}/{first}{j:02d}" for i in range(n) for j in range(k)]

        return make

    monkeypatch.setattr(train_mod, "make_samples", fake("range"))
    monkeypatch.setattr(train_mod, "make_mesh_samples", fake("mesh"))
    monkeypatch.setattr(train_mod, "make_stereo_samples", fake("stereo"))
    committed = [
        ("range", 1, 40, 8, None),
        ("mesh", 1, 10, 4, None),
        ("stereo", 1, 15, 4, None),
        ("brows", 1, 40, 2, None),
    ]
    names = train_mod._cached_samples(1, train_mod.DEFAULTS, None)
    assert calls == committed and len(names) == 320 + 40 + 60 + 80
    brows = names[420:]
    assert brows[:3] == ["train000/b00", "train000/b01", "train001/b00"]
    draws = {data._draw_label(np.random.default_rng(k), data.BROW_LABELS) for k in range(20)}
    assert draws == {"brows", "frown"}  # a raise and a frown, nothing else
    assert [train_mod._identity(n) for n in brows[:3]] == [0, 0, 1]  # their subjects' groups
    calls.clear()
    config = train_mod.DEFAULTS | {
        "extra_subjects": 3,
        "extra_wide_share": 0.65,
        "extra_knobs": ["width", "chin"],
    }
    more = train_mod._cached_samples(1, config, None)
    assert calls == [*committed, ("range", 1, 3, 8, data.FaceShares(1.0, 0.65, ("width", "chin")))]
    assert more[:500] == names and more[500:] == [
        f"wide{i:03d}/t{j:02d}" for i in range(3) for j in range(8)
    ]
    assert {train_mod._identity(n) for n in more[500:]} == {3000, 3001, 3002}
    with pytest.raises(InputError, match="extra_knobs: unknown"):
        train_mod.extra_shares(config | {"extra_knobs": ["ears"]})
    assert conventions == {"synth"}
    calls.clear()
    ibug = train_mod._cached_samples(1, config | {"convention": "ibug"}, None)
    assert ibug == more and calls[:4] == committed and conventions == {"synth", "ibug"}
    with pytest.raises(InputError, match="convention: expected one of"):
        train_mod._cached_samples(1, config | {"convention": "dlib"}, None)


def test_extra_subjects_leave_the_committed_takes_as_they_were(monkeypatch):
    """``make_samples`` without ``extra`` gives the committed recipe's takes (names and truth
    recorded from the code before the option existed, seed 1, 1 subject x 3 takes: the same
    random stream); with ``extra`` the takes are of other identities (``wide000``), with
    closed eyes at a closed-eye share of 1. Every take on sensors of half the size and focal
    length (the faces, poses and names do not depend on the size; a pixel centre x of the
    recorded 640 x 480 truth is at x / 2 - 0.25 on the 320 x 240 grid, whose principal point is
    at (w - 1) / 2: measured 2.5e-5 px off, the recording's rounding): 3 CPU-s instead of 6."""
    from scan2morph.landmarks import data
    from scan2morph.landmarks.data import FaceShares, make_samples, wide_identity
    from scan2morph.synth.cohort import subject_identity

    full_rgbd, full_scan, full_camera = data.make_rgbd_take, data.scan, data.camera_matrix
    half = {"width": 320, "height": 240, "focal_px": 300.0}
    half |= {"color_width": 320, "color_height": 240, "color_focal_px": 310.0}

    def small_rgbd(subject, label, kind, take, seed, params, *rest):
        return full_rgbd(subject, label, kind, take, seed, dict(params) | half, *rest)

    def small_scan(head, vertices, pose, K, width, height, *rest, **kw):
        return full_scan(head, vertices, pose, K, width // 2, height // 2, *rest, **kw)

    # the RGB-D sensor's size and focal lengths halved, and the range takes' 640 x 480 camera
    monkeypatch.setattr(data, "make_rgbd_take", small_rgbd)
    monkeypatch.setattr(data, "camera_matrix", lambda w, h, f: full_camera(w // 2, h // 2, f / 2))
    monkeypatch.setattr(data, "scan", small_scan)
    takes = make_samples(1, 1, 3)
    assert [t.name for t in takes] == [
        "train000/t00/neutral/colour",
        "train000/t01/too/colour",
        "train000/t02/car/rgbd",
    ]
    assert all(t.xyz.shape == (240, 320, 3) for t in takes)
    recorded = [  # points 31, 37, 46, 49 (px at 640 x 480), before the option
        [[257.1612, 240.7612], [195.524, 162.7048], [388.2137, 157.4122], [231.9704, 311.1007]],
        [[412.7959, 308.8673], [265.4409, 202.5848], [481.7921, 214.9995], [335.7187, 384.8792]],
        [[332.0241, 227.2917], [285.2921, 207.0264], [358.0361, 201.7713], [307.5737, 266.604]],
    ]
    for t, r in zip(takes, recorded, strict=True):  # 1e-3 px at 640 x 480
        np.testing.assert_allclose(t.truth[[30, 36, 45, 48]], np.array(r) / 2 - 0.25, atol=5e-4)
    shares = FaceShares(1.0, 1.0, ("chin",))
    face = wide_identity("wide000", 1, shares)
    own = subject_identity("wide000", 1)
    assert face.eyes_closed and face.chin != own.chin and face.nose == own.nose
    (extra,) = make_samples(1, 1, 1, shares)
    assert extra.name.endswith("/rgbd") and extra.xyz.shape == (240, 320, 3)
    assert extra.name.startswith("wide000/t00/")
    lids = [37, 38, 43, 44], [41, 40, 47, 46]  # upper and lower lid points of both eyes
    np.testing.assert_allclose(extra.truth[lids[0]], extra.truth[lids[1]], atol=1e-6)
    gaps = np.linalg.norm(takes[0].truth[lids[0]] - takes[0].truth[lids[1]], axis=1)
    assert (gaps > 5).all()  # 10 px at 640 x 480 (measured 9.0-10.4 px here)


def test_missing_model_is_named(tmp_path):
    with pytest.raises(InputError, match="landmark model not found"):
        load(tmp_path / "none.npz")


@pytest.mark.parametrize("n_samples", [30, 200])
def test_ridge_path_is_the_ridge_solution_with_few_or_many_samples(n_samples):
    """Against numpy's solve of the normal equations on the standardised features, for fewer
    samples than features (the kernel form) and for more (the Gram form), each penalty."""
    rng = np.random.default_rng(3)
    X = rng.normal(2.0, 3.0, size=(n_samples, 80))
    Y = X[:, :5] @ rng.normal(size=(5, 6)) + 0.1 * rng.normal(size=(n_samples, 6))
    ridges = [0.01, 1.0]
    stages = ridge_path(X, Y, 4.0, ridges)
    Xs = (X - X.mean(axis=0)) / X.std(axis=0)
    for ridge, stage in zip(ridges, stages, strict=True):
        lam = ridge * n_samples
        W = np.linalg.solve(Xs.T @ Xs + lam * np.eye(80), Xs.T @ (Y - Y.mean(axis=0)))
        np.testing.assert_allclose(stage.weights, W, rtol=0, atol=2e-6 * np.abs(W).max())
        assert stage.radius == 4.0


def test_a_denser_pattern_is_kept_in_the_model_file(tmp_path, tiny):
    """A cascade trained with a 5 x 5 pattern (``pattern_side``) reads 25 samples per point and
    channel, its file keeps the side and, read back, runs to the same shapes; the default
    3 x 3 pattern is :data:`PATTERN` and its file has no ``sides`` (the committed model's file
    as before)."""
    np.testing.assert_array_equal(pattern(3), PATTERN)
    config = TINY | {"pattern_side": 5}
    cache = tiny[1]  # the simulated takes (the pattern samples their images)
    model = train(5, config, cache=cache)
    local = model.stages[1:]
    assert [s.side for s in local] == [5, 5]
    channels = local[0].mean.size // (68 * 25)
    assert local[0].mean.size == 68 * 25 * channels
    save(model, tmp_path / "m.npz")
    back = load(tmp_path / "m.npz")
    assert [s.side for s in back.stages] == [3, 5, 5]  # the global stage's is unused
    rng = np.random.default_rng(0)
    chans = rng.random((320, 320, channels), dtype=np.float32)
    np.testing.assert_allclose(
        run(back, chans, model.init), run(model, chans, model.init), atol=0.05
    )
    save(train(5, config | {"pattern_side": 3}, cache=cache), tmp_path / "d.npz")
    with np.load(tmp_path / "d.npz") as z:
        assert "sides" not in z.files


def test_a_ridge_per_point_takes_each_points_columns_from_its_own_penalty():
    """With ``ridge_per_point`` each point's two weight columns are those of the stage fitted
    with that point's chosen penalty (the oracle: :func:`fit_stage` with each penalty); a point
    whose updates are exact in the features gets the smallest penalty, one whose updates are
    noise alone the largest."""
    rng = np.random.default_rng(7)
    X = rng.normal(size=(400, 20))
    Y = 0.3 * rng.normal(size=(400, 136))
    Y[:, :2] = X[:, :2] @ rng.normal(size=(2, 2))  # point 0: exact in the features
    Y[:, 2:4] = rng.normal(size=(400, 2))  # point 1: noise alone
    held = np.arange(400) % 5 == 4
    config = DEFAULTS | {"ridges": [0.001, 1.0, 1000.0], "ridge_per_point": True}
    stage, ridges = _fit_local(X, Y, held, 2.0, config)
    assert len(ridges) == 68 and ridges[0] == 0.001 and ridges[1] == 1000.0
    for point, ridge in enumerate(ridges):
        cols = slice(2 * point, 2 * point + 2)
        np.testing.assert_allclose(
            stage.weights[:, cols], fit_stage(X, Y, 2.0, ridge).weights[:, cols], atol=1e-6
        )
    one, ridge = _fit_local(X, Y, held, 2.0, config | {"ridge_per_point": False})
    assert np.isscalar(ridge) and one.weights.shape == stage.weights.shape
