"""Tests of the takes' consensus (scan2morph.refine.consensus, scan2morph.stages.consensus).

The known answer: takes that show one skin texture, each refined to it with its own smooth error
(the error a refinement by the surface's shape leaves), are each left with the takes' mean error:
the flow from the takes' mean image to each take's measures the take's error less the mean.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from scan2morph.errors import InputError
from scan2morph.geometry import face_sides
from scan2morph.refine import RefineParams
from scan2morph.refine.consensus import MIN_TAKES, take_consensus
from scan2morph.refine.template_space import template_grid
from scan2morph.stages import Subject, consensus
from scan2morph.stages.motion import aligned_mesh
from scan2morph.store import paths
from scan2morph.template import build_template, subdivide_template
from tests.support.configs import config_schema, repo_config

#: Pixels per template unit of the takes' images, and the template's origin in them, px.
SCALE, OFFSET = 60.0, 130.0


@pytest.fixture(scope="module")
def fine():
    return subdivide_template(build_template(), 1)


def _skin(shape, seed):
    """A skin-like texture: blurred noise, grey levels about 150 +- 25."""
    t = gaussian_filter(np.random.default_rng(seed).standard_normal(shape), 1.5)
    return 150.0 + 25.0 * t / t.std()


def _error(v2, rng, amplitude_px):
    """A smooth error field (V, 2) px: two plane waves per axis, about a face's width long."""
    out = np.zeros_like(v2)
    for axis in range(2):
        for _ in range(2):
            k = rng.normal(size=2) * 3.0  # radians per template unit: 0.5-1 waves a face
            out[:, axis] += amplitude_px * np.sin(v2 @ k + rng.uniform(0, 2 * np.pi))
    return out


@pytest.fixture(scope="module")
def takes(fine):
    """Six takes of one skin: each image the skin with its own sensor noise (1 grey level), each
    refined map the true one plus its own smooth error (RMS about 1.3 px)."""
    rng = np.random.default_rng(7)
    skin = _skin((300, 300), 3)
    truth = fine.vertices * SCALE + OFFSET
    names = [f"t{k}" for k in range(6)]
    images = {n: skin + rng.normal(0.0, 1.0, skin.shape) for n in names}
    errors = {n: _error(fine.vertices, rng, 1.0) for n in names}
    points = {n: truth + errors[n] for n in names}
    return truth, images, errors, points


def _outline(fine) -> np.ndarray:
    """(V,) bool: the template's outline vertices (on an edge of one triangle only)."""
    edges = np.sort(face_sides(fine.faces), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    out = np.zeros(len(fine.vertices), dtype=bool)
    out[unique[count == 1].ravel()] = True
    return out


def _rms(d, where):
    return float(np.sqrt(np.mean(np.sum(d[where] ** 2, axis=1))))


def test_each_take_is_left_with_the_takes_mean_error(fine, takes):
    """Each take's error about the takes' mean error falls from 1.0-1.4 px RMS to 0.04-0.07 inside
    the template and to 0.06-0.10 on its outline (measured; asserted below 0.15 of it: the maps
    reach beyond the outline, so that an outline vertex moves too), and the mean error stays
    (nothing can see it): the moved points' mean error is within 0.1 px RMS of it."""
    truth, images, errors, points = takes
    grid = template_grid(fine.vertices, fine.faces, 1.0 / SCALE, 24)
    moved, report = take_consensus(grid, fine.vertices, points, images, RefineParams(), 2, 0.3)
    mean_error = np.mean([errors[t] for t in points], axis=0)
    outline = _outline(fine)
    for take in points:
        for where in (~outline, outline):
            before = _rms(errors[take] - mean_error, where)
            after = _rms(moved[take] - truth - mean_error, where)
            print(f"{take}: {before:.3f} -> {after:.3f} px", report[take])
            assert before > 0.5
            assert after < 0.15 * before, take
        assert report[take]["kept"] and report[take]["confident_share"] > 0.9
    left = np.mean([moved[t] - truth for t in points], axis=0)
    every = np.ones(len(truth), dtype=bool)
    print(f"the takes' mean error moved by {_rms(left - mean_error, every):.3f} px")
    assert _rms(left - mean_error, every) < 0.1


def test_a_take_whose_texture_is_not_the_others_is_left_out(fine, takes):
    """A take showing another skin measures 0.15 of the template against the others' mean
    (the others: 1.0); below refine.min_confident_share (0.3) it is left out and the others are
    registered without it: each left with their own mean error (within 0.15 of its own)."""
    truth, images, errors, points = takes
    grid = template_grid(fine.vertices, fine.faces, 1.0 / SCALE, 24)
    stranger = list(points)[-1]
    other = dict(images) | {stranger: _skin((300, 300), 99)}
    moved, report = take_consensus(grid, fine.vertices, points, other, RefineParams(), 2, 0.3)
    assert not report[stranger]["kept"] and report[stranger]["confident_share"] < 0.3
    assert stranger not in moved and len(moved) == len(points) - 1
    mean_error = np.mean([errors[t] for t in moved], axis=0)
    inside = ~_outline(fine)
    for take in moved:
        before = _rms(errors[take] - mean_error, inside)
        assert _rms(moved[take] - truth - mean_error, inside) < 0.15 * before, take
    # with every take but two left out, nothing moves
    few = dict(other) | {t: _skin((300, 300), 100 + k) for k, t in enumerate(list(points)[:3])}
    moved, report = take_consensus(grid, fine.vertices, points, few, RefineParams(), 1, 0.3)
    assert moved == {} and not any(r["kept"] for r in report.values())


def test_a_consensus_needs_three_takes_and_a_round(fine, takes):
    truth, images, _, points = takes
    grid = template_grid(fine.vertices, fine.faces, 1.0 / SCALE, 24)
    two = {t: points[t] for t in list(points)[:2]}
    with pytest.raises(ValueError, match=f"at least {MIN_TAKES} takes"):
        take_consensus(grid, fine.vertices, two, images, RefineParams())
    with pytest.raises(ValueError, match="rounds: expected at least 1"):
        take_consensus(grid, fine.vertices, points, images, RefineParams(), 0)


def _verdicts(shape_used: dict) -> dict:
    """A subject's data holding only each take's refine verdict (and refined points)."""
    data = {}
    for take, used in shape_used.items():
        data[paths.refine_group(take)] = {"shape_used": used}
        data[paths.refine(take, "points2d")] = np.zeros((4, 2))
    return data


def test_the_members_are_the_takes_refined_by_their_shape():
    """Only takes whose refinement used the surface's shape take part; the neutral never; with
    fewer than three the stage writes nothing and says why."""
    kinds = {"n": "neutral", "a": "viseme", "b": "expression", "c": "viseme", "d": "expression"}
    subject = Subject("s", kinds, {t: t for t in kinds})
    verdicts = {"n": True, "a": True, "b": False, "c": True, "d": True}
    assert consensus.members(subject, _verdicts(verdicts)) == ["a", "c", "d"]
    params = consensus.Params.from_config(repo_config())
    assert params.use and params.rounds == 2
    part = consensus.run(None, subject, _verdicts(verdicts | {"d": False}), params)
    assert part.datasets == {}
    attrs = part.attrs[paths.CONSENSUS]
    assert attrs["used"] is False and "2 take(s) refined by their shape" in attrs["problem"]
    config = repo_config()
    config["refine"]["consensus"] = {"use": False}
    part = consensus.run(None, subject, _verdicts(verdicts), consensus.Params.from_config(config))
    assert part.datasets == {} and "off" in part.attrs[paths.CONSENSUS]["problem"]
    config["refine"] = {**config["refine"], "method": "none", "consensus": {"use": True}}
    assert not consensus.Params.from_config(config).use


@pytest.fixture(scope="module")
def schema_validator():
    """The config schema's validator, the schema checked against its meta-schema once (as
    ``jsonschema.validate`` does on every call: 0.2 CPU-s each)."""
    import jsonschema

    schema = config_schema()
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


@pytest.mark.parametrize("rounds", [0, -1, 1.5, True, "2"])
def test_a_bad_rounds_value_is_refused_naming_the_key(rounds, schema_validator):
    import jsonschema

    config = repo_config()
    config["refine"]["consensus"] = {"use": True, "rounds": rounds}
    with pytest.raises(InputError, match="refine.consensus.rounds"):
        consensus.Params.from_config(config)
    with pytest.raises(jsonschema.ValidationError):
        schema_validator.validate(config)


def test_the_motion_stage_compares_the_consensus_mesh_where_there_is_one():
    refined = {
        paths.refine("a", "vertices"): np.zeros((3, 3)),
        paths.refine("a", "valid"): np.ones(3, bool),
        paths.refine("a", "confidence"): np.full(3, 0.5),
    }
    assert np.array_equal(aligned_mesh(refined, "a", "s", refined=True).vertices, np.zeros((3, 3)))
    moved = refined | {
        paths.consensus("a", "vertices"): np.ones((3, 3)),
        paths.consensus("a", "valid"): np.array([True, False, True]),
    }
    mesh = aligned_mesh(moved, "a", "s", refined=True)
    assert np.array_equal(mesh.vertices, np.ones((3, 3)))
    assert np.array_equal(mesh.valid, [True, False, True])
    assert np.array_equal(mesh.confidence, np.full(3, 0.5))
