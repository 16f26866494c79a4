"""Tests of scan2morph.refine.memo: the work the click-noise draws share is computed once, and
the refinement gives the same numbers, bit for bit, with and without the sharing."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from scan2morph.refine import RefineParams, refine_points
from scan2morph.refine.lip import LipParams
from scan2morph.refine.memo import active, digest, shared, sharing
from scan2morph.template import build_template, subdivide_template
from scan2morph.template.fit import fit_map
from scan2morph.template.sample import _partial_weights, sample_range
from tests.unit.test_lip import _prior, _scene
from tests.unit.test_refine import _texture, _warp


def test_digest_tells_dtype_shape_and_values_apart():
    a = np.arange(6.0)
    assert digest(a) == digest(a.copy()) == digest(np.arange(6.0)[::1])
    assert digest(a) != digest(a.astype(np.float32))
    assert digest(a) != digest(a.reshape(2, 3))
    b = a.copy()
    b[3] += 1e-12
    assert digest(a) != digest(b)
    assert digest(a[::2]) == digest(np.array([0.0, 2.0, 4.0]))  # a view: its own values
    assert digest(a, 1.0) != digest(a, 1)  # a number's repr: 1.0 and 1 are two inputs


def test_a_step_is_computed_once_in_a_scope_and_every_time_outside():
    calls = []

    def compute():
        calls.append(1)
        return np.ones(3), 2.0

    assert not active()
    shared("step", (np.zeros(2),), compute)
    shared("step", (np.zeros(2),), compute)
    assert len(calls) == 2
    with sharing() as counts:
        assert active()
        first = shared("step", (np.zeros(2),), compute)
        again = shared("step", (np.zeros(2),), compute)
        shared("step", (np.ones(2),), compute)  # another input
        shared("other", (np.zeros(2),), compute)  # another step
        assert again is first
        assert counts == {"step": [1, 2], "other": [0, 1]}
        with pytest.raises(ValueError, match="read-only"):
            first[0][0] = 5.0  # no caller changes what another is handed
    assert not active()
    assert len(calls) == 5


def test_a_scope_keeps_at_most_its_bytes():
    with sharing(kept_bytes=3 * 800) as counts:
        for k in range(5):  # five results of 800 bytes: the first two are let go
            shared("step", (k,), lambda: np.zeros(100))
        for k in (4, 3, 2, 0):
            shared("step", (k,), lambda: np.zeros(100))
    assert counts == {"step": [3, 6]}


def test_the_corner_fits_are_the_pseudo_inverse_of_each_pattern():
    """:func:`_partial_weights` keeps each pattern's pseudo-inverse: the weights are those of
    the least-squares affine fit through the corners with data, for all 15 patterns."""
    rng = np.random.default_rng(5)
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=np.float64)
    for code in range(1, 16):
        used = np.flatnonzero((code >> np.arange(4)) & 1)
        fx, fy = rng.uniform(0, 1, 7), rng.uniform(0, 1, 7)
        have = np.zeros((4, 7), dtype=bool)
        have[used] = True
        centre = corners[used].mean(axis=0)
        design = np.column_stack([np.ones(len(used)), corners[used] - centre])
        at = np.column_stack([np.ones(7), fx - centre[0], fy - centre[1]])
        expected = np.zeros((4, 7))
        expected[used] = (at @ np.linalg.pinv(design)).T
        assert_array_equal(_partial_weights(fx, fy, have), expected)
    # several patterns at once: each point's weights as when alone; no points, no weights
    fx, fy = rng.uniform(0, 1, 40), rng.uniform(0, 1, 40)
    have = rng.random((4, 40)) < 0.6
    have[:, 0] = False
    alone = np.column_stack(
        [_partial_weights(fx[[i]], fy[[i]], have[:, [i]])[:, 0] for i in range(40)]
    )
    np.testing.assert_allclose(_partial_weights(fx, fy, have), alone, rtol=0, atol=1e-15)
    assert _partial_weights(fx[:0], fy[:0], have[:, :0]).shape == (4, 0)
    # a sample of a plane with a missing corner is the plane's value
    xyz = np.stack([*np.meshgrid(np.arange(6.0), np.arange(5.0)), np.ones((5, 6))], axis=-1)
    xyz[2, 3] = np.nan
    out, ok = sample_range(xyz, np.array([[2.5, 1.5], [3.25, 2.5]]), min_weight=0.5)
    assert ok.all()
    np.testing.assert_allclose(out[:, :2], [[2.5, 1.5], [3.25, 2.5]], atol=1e-12)


@pytest.fixture(scope="module")
def refinements():
    """Two takes refined against one fit of the neutral (a textured image, the take's skin
    slid by a known field), by thin-plate splines through slightly different clicks."""
    template = build_template()
    fine = subdivide_template(template, 1)
    neutral = _texture((240, 320), 4)
    yy, xx = np.mgrid[0:240, 0:320].astype(np.float64)
    ux = 2.0 * np.exp(-(((xx - 160) / 35) ** 2 + ((yy - 130) / 30) ** 2))
    takes = [_warp(neutral, -ux, -0.5 * ux), _warp(neutral, 0.5 * ux, ux)]
    clicks = np.array([160.0, 120.0]) + 75.0 * template.ibug_xy
    rng = np.random.default_rng(3)
    maps = [fit_map(template, clicks + rng.normal(0, 0.5, clicks.shape)) for _ in range(3)]
    _, anchors = template.fiducial_set("closed")
    params = RefineParams(iterations=2)

    def run():
        return [
            refine_points(fine.vertices, fine.faces, maps[0], m, neutral, t, anchors, params)
            for m, t in zip(maps[1:], takes, strict=True)
        ]

    return run


def test_refinements_sharing_the_neutral_give_the_straightforward_numbers(refinements):
    plain = refinements()
    with sharing() as counts:
        shared_ = refinements()
    # the neutral's side and its flow side were computed once for both takes and both rounds
    assert counts["neutral"] == [1, 1]
    assert counts["flow_reference"] == [3, 1]
    for (p, report), (q, again) in zip(plain, shared_, strict=True):
        assert_array_equal(p, q)
        for key in ("correction", "confidence"):
            assert_array_equal(report[key], again[key])
        assert report["confident_share"] == again["confident_share"]
    assert report["confident_share"] > 0.3  # the refinement measured something


def test_lip_priors_sharing_the_neutrals_profiles_give_the_straightforward_numbers():
    s = _scene()
    flows = [s["flow"], s["flow"] + np.array([0.0, 0.6])]
    plain = [_prior(s, LipParams(), flow=f) for f in flows]
    with sharing() as counts:
        again = [_prior(s, LipParams(), flow=f) for f in flows]
    assert counts["lip_profiles"] == [1, 1] and counts["redness"] == [2, 2]
    for a, b in zip(plain, again, strict=True):
        assert a.used and b.used
        assert_array_equal(a.points, b.points)
        assert_array_equal(a.weight, b.weight)
        assert (a.measured, a.contrast) == (b.measured, b.contrast)


def test_refine_stage_shares_in_its_own_scope_or_in_the_callers(monkeypatch):
    """The refine stage runs a take in a sharing scope of its own (the reference's high-pass
    of every round computed once), and in its caller's when one is open (a click-noise draw's,
    shared across the takes)."""
    from scan2morph.refine import memo
    from scan2morph.stages import refine as refine_stage
    from scan2morph.stages.part import Take
    from scan2morph.store import paths

    scopes = []
    monkeypatch.setattr(
        refine_stage, "_refine", lambda template, take, params: scopes.append(list(memo._SCOPES))
    )
    data = {
        paths.align("car", "vertices"): np.zeros((3, 3)),
        paths.mesh("car", "valid"): np.ones(3, bool),
        paths.mesh("car", "points2d"): np.zeros((3, 2)),
    }
    take = Take("s", "car", "viseme", "car", "neutral", data=data)
    refine_stage.run(None, take, None)
    assert len(scopes[0]) == 1 and not active()  # its own, closed after
    with sharing():
        outer = list(memo._SCOPES)
        refine_stage.run(None, take, None)
    assert scopes[1] == outer  # the caller's, no other


def _fuse_oracle(measured, weight, inside, smooth, prior, anchors, anchor_weight):
    """The fusion's system built otherwise (the grid's neighbours as a Kronecker sum, cut to
    ``inside``) and solved from scratch (COLAMD's own order, every time)."""
    from scipy import sparse
    from scipy.sparse.linalg import splu

    def path(n):  # neighbours along one axis
        return sparse.diags([np.ones(n - 1), np.ones(n - 1)], [-1, 1])

    rows, cols = inside.shape
    grid = sparse.kron(sparse.eye(rows), path(cols)) + sparse.kron(path(rows), sparse.eye(cols))
    keep = np.flatnonzero(inside.ravel())
    adjacent = grid.tocsr()[keep][:, keep]
    deg = np.asarray(adjacent.sum(axis=1)).ravel()
    w = weight[inside]
    diag = w + prior**2 / (w + prior)
    number = np.full(inside.size, -1)
    number[keep] = np.arange(len(keep))
    at = number[anchors[:, 0] * cols + anchors[:, 1]]
    np.add.at(diag, at[at >= 0], anchor_weight)
    system = (sparse.diags(diag + smooth * deg) - smooth * adjacent).tocsc()
    system.eliminate_zeros()
    system.sort_indices()
    lu = splu(system)
    out = np.zeros((rows, cols, 2))
    for k in range(2):
        out[..., k][inside] = lu.solve(w * measured[..., k][inside])
    return out


@pytest.mark.parametrize("smooth", [256.0, 0.0])
def test_fusions_sharing_a_grid_give_the_straightforward_numbers(smooth):
    """:func:`fuse` keeps each grid's membrane and fill-reducing order in a sharing scope: the
    rounds of a refinement (other weights on one grid) solve as the system built afresh does,
    bit for bit, in the scope and out of it; without a membrane (``smooth`` 0, whose terms
    would leave the sum) the system is built as it is."""
    from scan2morph.refine.flow import fuse

    rng, prior = np.random.default_rng(11), 2.5
    yy, xx = np.mgrid[0:70, 0:90]
    inside = ((xx - 45) / 40.0) ** 2 + ((yy - 35) / 30.0) ** 2 < 1.0  # an irregular domain
    anchors = np.array([[35, 45], [20, 30], [50, 60], [0, 0]])  # the last one outside
    cases = []
    for _ in range(3):
        measured = rng.normal(0.0, 1.0, (70, 90, 2))
        weight = np.where(rng.random((70, 90)) < 0.6, rng.uniform(0.0, 16.0, (70, 90)), 0.0)
        cases.append((measured, weight))
    expected = [_fuse_oracle(m, w, inside, smooth, prior, anchors, 2.0) for m, w in cases]
    plain = [fuse(m, w, inside, smooth, prior, anchors, 2.0) for m, w in cases]
    with sharing() as counts:
        again = [fuse(m, w, inside, smooth, prior, anchors, 2.0) for m, w in cases]
    for e, p, q in zip(expected, plain, again, strict=True):
        assert_array_equal(p, e)
        assert_array_equal(q, e)
    assert counts["membrane"] == [2, 1] and counts["fill_order"] == [2, 1]  # found once
    assert np.abs(expected[0]).max() > 0.1  # something was fused
