"""The forehead rim of a take's fit (scan2morph.template.rim): analytic checks of the spline."""

from __future__ import annotations

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.template import build_template, fit_map, subdivide_template
from scan2morph.template.rim import BROWS, Rim, rim_vertices, still_affine
from tests.support.configs import config_schema, repo_config


@pytest.fixture(scope="module")
def template():
    return build_template()


def _neutral(template, seed=3):
    """A neutral's 68 landmarks, px: the canonical face scaled to pixels, bent by a smooth
    identity warp (so that it is not the template's own shape)."""
    rng = np.random.default_rng(seed)
    xy = template.ibug_xy
    bend = np.column_stack([0.06 * xy[:, 1] ** 2, 0.05 * xy[:, 0] * xy[:, 1]])
    return np.array([320.0, 200.0]) + 75 * (xy + bend) + rng.normal(0, 0.4, xy.shape)


def test_the_rim_is_the_outline_above_the_brows(template):
    rim = rim_vertices(template)
    brow_y = template.ibug_xy[np.array(BROWS) - 1, 1].mean()
    assert set(rim) <= set(template.boundary.tolist())
    assert np.all(template.vertices[rim, 1] < brow_y)
    others = np.setdiff1d(template.boundary, rim)
    assert np.all(template.vertices[others, 1] >= brow_y)
    assert 15 <= len(rim) <= 40


@pytest.mark.parametrize("share", [0.0, 0.5])
def test_a_take_moved_by_an_affine_map_keeps_the_plain_spline(template, share):
    """The thin-plate spline is affine-equivariant: a take whose landmarks are an affine image
    of the neutral's has the neutral's spline composed with that map, so its rim, placed from
    the neutral's by the same map, is where its plain spline puts it: the two maps agree at
    every fine vertex (the rim adds points, not motion)."""
    neutral = _neutral(template)
    a = np.array([[12.0, -7.0], [0.97, 0.06], [-0.04, 1.02]])  # [1, x, y] @ a
    take = np.column_stack([np.ones(68), neutral]) @ a
    fine = subdivide_template(template, 1).vertices
    plain = fit_map(template, take, "closed")(fine)
    anchored = fit_map(template, take, "closed", rim=Rim(neutral, "closed", share))(fine)
    np.testing.assert_allclose(still_affine(neutral, take), a, atol=1e-9)
    assert np.max(np.abs(anchored - plain)) < 1e-6


def test_a_brow_raise_moves_the_rim_by_its_share(template):
    """The brows (iBUG 18-27) rise by 8 px and nothing else moves. The plain spline carries
    the rim further than the brows (its extrapolation); the anchored spline keeps ``share`` of
    that motion exactly and still interpolates every fiducial, and the lips move by less than a
    hundredth of the rim's change (measured: the plain rim 19.4 px, the lips 0.04 px at
    share 0)."""
    neutral = _neutral(template)
    take = neutral.copy()
    take[np.array(BROWS) - 1, 1] -= 8.0
    rim = template.vertices[rim_vertices(template)]
    before = fit_map(template, neutral, "closed")(rim)
    plain = fit_map(template, take, "closed")(rim) - before
    assert np.max(np.linalg.norm(plain, axis=1)) > 2 * 8.0  # the spline overshoots the brows
    numbers, idx = template.fiducial_set("closed")
    lips = template.vertices[template.ibug_vertex[np.arange(48, 68)]]
    plain_lips = fit_map(template, take, "closed")(lips)
    for share in (0.0, 0.3, 1.0):
        spline = fit_map(template, take, "closed", rim=Rim(neutral, "closed", share))
        np.testing.assert_allclose(spline(rim) - before, share * plain, atol=1e-6)
        np.testing.assert_allclose(spline(template.vertices[idx]), take[numbers - 1], atol=1e-6)
        shift = np.linalg.norm(spline(lips) - plain_lips, axis=1).max()
        assert shift < 0.01 * (1 - share) * np.linalg.norm(plain, axis=1).max() + 1e-9


@pytest.mark.parametrize("share", [-0.1, 1.5, float("nan"), "half"])
def test_a_rim_share_outside_0_1_is_refused(share):
    with pytest.raises(InputError, match="Rim.*share"):
        Rim(np.zeros((68, 2)), "closed", share)


def test_still_points_on_one_line_or_missing_are_refused(template):
    neutral = _neutral(template)
    line = neutral.copy()
    line[:, 1] = 200.0
    with pytest.raises(InputError, match="a/b.*one line"):
        still_affine(line, neutral, "a/b")
    gone = neutral.copy()
    gone[30] = np.nan  # iBUG 31, the nose tip
    with pytest.raises(InputError, match=r"a/b.*landmarks: expected \(68, 2\) finite px"):
        still_affine(neutral, gone, "a/b")
    with pytest.raises(InputError, match="neutral landmarks"):
        still_affine(neutral[:60], neutral, "a/b")


def test_the_fit_stage_places_a_takes_rim_from_its_neutral(template):
    """The fit stage fits the neutral with its plain spline and a take with its rim placed from
    the neutral's landmarks (``template.rim_share``), records the share it used, and names the
    neutral's landmarks when they are missing."""
    from scan2morph.stages import fit as fit_stage
    from scan2morph.stages.part import Take
    from scan2morph.store import paths
    from scan2morph.template import FitRules, fit_take

    y, x = np.mgrid[0:480, 0:640].astype(np.float64)
    xyz = np.stack([0.5 * x, 0.5 * y, 900.0 + 0.0 * x], axis=-1)
    neutral = _neutral(template)
    raised = neutral.copy()
    raised[np.array(BROWS) - 1, 1] -= 8.0
    data = {paths.landmarks("n"): neutral, paths.landmarks("b"): raised}
    data |= {paths.range_image(t, "xyz"): xyz for t in ("n", "b")}
    params = fit_stage.Params({}, FitRules(levels=1), rim_share=0.5)
    for take, lm, rim, share in (
        ("n", neutral, None, 1.0),
        ("b", raised, Rim(neutral, "closed", 0.5), 0.5),
    ):
        part = fit_stage.run(template, Take("s", take, "expression", take, "n", data), params)
        want = fit_take(template, lm, xyz, rules=FitRules(levels=1), rim=rim)
        np.testing.assert_array_equal(part.datasets[paths.mesh(take, "points2d")], want["points2d"])
        assert part.attrs[paths.take(take)]["rim_share"] == share
    plain = fit_take(template, raised, xyz, rules=FitRules(levels=1))["points2d"]
    assert np.abs(part.datasets[paths.mesh("b", "points2d")] - plain).max() > 4.0
    del data[paths.landmarks("n")]
    with pytest.raises(InputError, match=r"s/b.*takes/n/landmarks: missing"):
        fit_stage.run(template, Take("s", "b", "expression", "b", "n", data), params)


def test_the_rim_share_default_agrees_in_config_schema_and_library():
    """``template.rim_share``: config/config.yaml, the schema's default, the fit stage's
    ``Params`` and :class:`Rim` give one value."""
    import dataclasses

    from scan2morph.stages import fit as fit_stage

    config = repo_config()["template"]
    schema = config_schema()
    spec = schema["properties"]["template"]["properties"]["rim_share"]["default"]
    defaults = {f.name: f.default for f in dataclasses.fields(fit_stage.Params)}
    rim = {f.name: f.default for f in dataclasses.fields(Rim)}
    assert config["rim_share"] == spec == defaults["rim_share"] == rim["share"] == 0.5
