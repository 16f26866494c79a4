"""The still skin of a take (scan2morph.align.still): a forehead that moves with the brows."""

from __future__ import annotations

import numpy as np
import pytest

from scan2morph.align import AlignMeshes, IcpParams, align_take
from scan2morph.align.rigid import invert, transform_points
from scan2morph.align.still import patches
from scan2morph.errors import InputError
from tests.unit.test_align import PAIR_XY, _errors, _face, _rigid


def _forehead_raise(v: np.ndarray, mm: float, wide: float = 30.0) -> np.ndarray:
    """A strong brow raise (AU1+2) that carries the whole forehead: the brows rise ``mm`` and
    the forehead above slides up with them, fading slowly towards the hairline (to 0.7 of it
    50 mm above the brows) and to the sides (scale ``wide``, mm); the upper lids below follow a
    little."""
    x, y = v[:, 0], v[:, 1]
    w = np.exp(-(((np.abs(x) - 10.0) / wide) ** 2)) * np.where(
        y >= 48.0, np.exp(-(((y - 48.0) / 90.0) ** 2)), np.exp(-(((y - 48.0) / 8.0) ** 2))
    )
    return mm * w[:, None] * np.array([0.0, 1.0, 0.0])


def _brow_scene(seed: int, brow_mm: float, wide: float = 30.0):
    """A neutral and a take whose forehead moved with the brows (:func:`_forehead_raise`),
    the take moved by a known 5 deg / 10 mm rigid motion, 0.1 mm noise; the region assumed
    still: the upper forehead, the nose ridge and the temples (as the template's ``stable``
    region), growing into the face above the mouth."""
    rng = np.random.default_rng(seed)
    v, f = _face()
    x, y = v[:, 0], v[:, 1]
    pairs = np.array([np.argmin(np.linalg.norm(v[:, :2] - p, axis=1)) for p in PAIR_XY])
    stable = np.flatnonzero(
        (y > 64) | ((np.abs(x) < 10) & (y > 0) & (y < 45)) | ((np.abs(x) > 60) & (y > 10))
    )
    upper = np.flatnonzero(y > -15)
    frame = _rigid(rng, 40, 300)
    neutral = transform_points(frame, v)
    truth = _rigid(rng, 5, 10)
    take = transform_points(
        invert(truth), transform_points(frame, v + _forehead_raise(v, brow_mm, wide))
    )
    take += rng.normal(scale=0.1, size=v.shape)
    valid = np.ones(len(v), dtype=bool)
    meshes = AlignMeshes(take, valid, neutral, valid, f)
    return meshes, pairs, stable, upper, truth, neutral[upper].mean(axis=0)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_still_skin_is_found_when_the_forehead_moves(seed):
    """Oracle: the known rigid motion. The region assumed still is mostly forehead, which slides
    up 6 mm with the brows: the assumption (trimming and growth included) follows the forehead,
    degrees and millimetres off (and flagged); the search for the still skin recovers the pose
    within 0.1 degrees / 0.1 mm."""
    meshes, pairs, stable, upper, truth, centre = _brow_scene(seed, 6.0)
    old = align_take(meshes, pairs, stable, IcpParams(kernel_k_mm=0.3), "s01/brows", upper)
    new = align_take(
        meshes, pairs, stable, IcpParams(kernel_k_mm=0.3, still_groups=6), "s01/brows", upper
    )
    rot0, t0 = _errors(old.transform, truth, centre)
    rot, t = _errors(new.transform, truth, centre)
    assert rot0 > 2.0 and t0 > 5.0, (rot0, t0)
    assert rot < 0.1 and t < 0.1, (rot, t, "assumed still:", rot0, t0)
    assert new.ok, new.problems
    assert any(r.startswith("still skin") for r in new.recovery)


def test_a_wide_forehead_raise_passes_the_old_gate_and_is_found_by_the_search():
    """The forehead and the temples slide up: the assumption is 1.5 degrees off and passes its
    own gate (the moving skin is rigid enough); the search finds the still skin, within the
    alignment goal (0.2 degrees / 0.3 mm)."""
    meshes, pairs, stable, upper, truth, centre = _brow_scene(1, 6.0, wide=60.0)
    old = align_take(meshes, pairs, stable, IcpParams(kernel_k_mm=0.3), "s01/brows", upper)
    new = align_take(
        meshes, pairs, stable, IcpParams(kernel_k_mm=0.3, still_groups=6), "s01/brows", upper
    )
    rot0, t0 = _errors(old.transform, truth, centre)
    rot, t = _errors(new.transform, truth, centre)
    assert old.ok and rot0 > 1.0 and t0 > 5.0, (old.ok, rot0, t0)
    assert rot < 0.2 and t < 0.3, (rot, t)


def test_a_still_take_keeps_its_pose_with_the_search():
    """Nothing moved: the search keeps (nearly) every candidate and the same pose."""
    meshes, pairs, stable, upper, truth, centre = _brow_scene(3, 0.0)
    new = align_take(meshes, pairs, stable, IcpParams(still_groups=6), "s01/neutral2", upper)
    rot, t = _errors(new.transform, truth, centre)
    assert rot < 0.05 and t < 0.05, (rot, t)
    assert new.ok and new.inlier_fraction > 0.9, (new.ok, new.inlier_fraction)


def test_patches_are_compact_and_deterministic():
    # four clusters far apart: four patches, one per cluster
    rng = np.random.default_rng(0)
    centres = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100]], dtype=float)
    p = np.concatenate([c + rng.normal(scale=3.0, size=(50, 3)) for c in centres])
    labels = patches(p, 4)
    assert np.array_equal(labels, patches(p, 4))
    for i in range(4):
        assert len(np.unique(labels[i * 50 : (i + 1) * 50])) == 1
    assert len(np.unique(labels)) == 4


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"still_groups": -1}, "still_groups must be an integer >= 0"),
        ({"still_groups": 2.5}, "still_groups must be an integer >= 0"),
        ({"still_drop": 0}, "still_drop must be an integer >= 1"),
        ({"still_drop": True}, "still_drop must be an integer >= 1"),
    ],
)
def test_still_settings_bad_input(change, match):
    with pytest.raises(InputError, match=match):
        IcpParams(**change)


def test_without_any_patch_pose_the_regions_trimmed_pose_is_kept():
    """When no set of patches gives a finite pose (every refit fails), the search keeps what
    the region's trimming found instead of refitting on every candidate, and says so."""
    from types import SimpleNamespace

    from scan2morph.align.icp import _found_still

    v, _ = _face()
    keep = v[:, 1] > 64.0
    t = _rigid(np.random.default_rng(3), 2, 5)
    calls = []

    def failing(use, start):
        calls.append(int(use.sum()))
        return np.full((4, 4), np.nan), 0.0, np.nan, 3, False

    s = SimpleNamespace(p=v, plane=lambda x: np.zeros(len(x)))
    out = _found_still(s, (keep, t, True), failing, IcpParams(still_groups=6))
    assert len(calls) == 1 + 6 + 15  # none, each one and each pair of the 6 patches left out
    assert out[0] is keep and out[1] is t and out[2] is True
    assert out[3] == 3 * len(calls)
    assert "the region's trimmed pose is kept" in out[4][-1]
