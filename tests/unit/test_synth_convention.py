"""The truth's landmark conventions (issue #33): the default is the generator's own, unchanged;
``ibug`` follows our hand annotation's rules (tests/support/lps_landmarks.py)."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals
from scan2morph.synth.cohort import AIM, articulated_head, make_take
from scan2morph.synth.convention import SILHOUETTE_DEG, landmark_vertices
from scan2morph.synth.ibug import BROW_ENDS_MM
from scan2morph.synth.scanner import camera_matrix, head_pose, project, render


@pytest.fixture(scope="module")
def take():
    """A neutral head with open eyes, straight in front of a 640 x 480 camera."""
    head, vertices, _ = articulated_head("synth02", "neutral", "neutral", "t", 3)
    pose = head_pose(np.random.default_rng(0), 650.0, 0.0, 0.0, AIM)
    lm = landmark_vertices(head, vertices, pose, "ibug")
    return head, vertices, pose, camera_matrix(640, 480, 1000.0), lm


def test_default_convention_is_todays_truth():
    """The default gives the truth of main before the switch existed, bit for bit, and is the
    ``synth`` convention (an equality: on a 160 x 120 take of the same face)."""
    r = make_take("synth01", "smile", "expression", "smile1", 7)
    small = {"width": 160, "height": 120, "focal_px": 362.5}
    default = make_take("synth01", "smile", "expression", "smile1", 7, small)
    same = make_take("synth01", "smile", "expression", "smile1", 7, small, convention="synth")
    for key in ("landmarks3d", "landmarks2d"):
        np.testing.assert_array_equal(default["truth"][key], same["truth"][key])
    t = r["truth"]
    head, vertices, _ = articulated_head("synth01", "smile", "expression", "smile1", 7)
    lm3 = vertices[head.landmarks] @ t["pose"][:3, :3].T + t["pose"][:3, 3]
    np.testing.assert_array_equal(t["landmarks3d"], lm3)
    assert landmark_vertices(head, vertices, t["pose"]) is head.landmarks
    # sha256 of the three arrays as main (fbd29d2) wrote them
    blob = b"".join(
        np.ascontiguousarray(a).tobytes() for a in (lm3, t["landmarks2d"], r["landmarks"])
    )
    assert hashlib.sha256(blob).hexdigest()[:16] == "2a6889d4816e2c2a"


def test_unknown_convention_is_refused(take):
    head, vertices, pose, _, _ = take
    with pytest.raises(InputError, match="convention"):
        landmark_vertices(head, vertices, pose, "300w")


def test_jaw_on_the_silhouette(take):
    """Each jaw point's surface turns up to 72 degrees from the view ray, and 3 px beyond it
    (away from the mouth) the rendered surface falls at least 2 mm away: the face's outline."""
    head, vertices, pose, K, lm = take
    cam = vertices @ pose[:3, :3].T + pose[:3, 3]
    normals = vertex_normals(vertices, head.faces, fill=0.0) @ pose[:3, :3].T
    ray = cam[lm[:17]] / np.linalg.norm(cam[lm[:17]], axis=1, keepdims=True)
    angle = np.degrees(np.arccos(-np.sum(normals[lm[:17]] * ray, axis=1)))
    assert np.all(angle < SILHOUETTE_DEG) and np.median(angle) > 60.0
    _, depth, _ = render(head, vertices, pose, K, 640, 480)
    uv = project(K, cam[lm[:17]])
    mouth = project(K, cam[np.r_[head.slit_upper, head.slit_lower]].mean(0)[None])[0]
    for p, z in zip(uv, cam[lm[:17], 2], strict=True):
        q = np.round(p + 3.0 * (p - mouth) / np.linalg.norm(p - mouth)).astype(int)
        beyond = depth[q[1], q[0]]
        assert not beyond > 0 or beyond - z > 2.0
    # 17 points at about equal steps, from 6 mm below the outer eye corners round the chin
    steps = np.linalg.norm(np.diff(uv, axis=0), axis=1)
    assert steps.std() / steps.mean() < 0.35
    top = head.vertices[head.landmarks[[36, 45]], 1].mean() - 6.0
    np.testing.assert_allclose(head.vertices[lm[[0, 16]], 1], top, atol=2.0)
    assert uv[0, 0] < uv[8, 0] < uv[16, 0]  # iBUG 1 on the subject's right (image left)


def test_jaw_follows_the_view(take):
    """Turned 20 degrees, the jawline moves with the silhouette: not the same vertices."""
    head, vertices, pose, _, lm = take
    turn = np.eye(4)
    c, s = np.cos(np.deg2rad(20.0)), np.sin(np.deg2rad(20.0))
    turn[:3, :3] = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
    turned = landmark_vertices(head, vertices, turn @ pose, "ibug")
    assert np.sum(turned[:17] != lm[:17]) >= 10
    np.testing.assert_array_equal(turned[17:], lm[17:])


def test_bridge_from_the_inner_corners_height(take):
    """28 on the midline at the inner eye corners' height, 29 and 30 evenly down to 31."""
    head, _, _, _, lm = take
    rest = head.vertices
    assert abs(rest[lm[27], 0]) < 1.0
    assert abs(rest[lm[27], 1] - rest[head.landmarks[[39, 42]], 1].mean()) < 1.0
    steps = np.diff(rest[lm[27:31], 1])
    np.testing.assert_allclose(steps, steps.mean(), atol=1.5)


def test_lid_points_at_thirds(take):
    """Open eyes: the lid points a third and two thirds of the way between the corners, the
    upper ones above the corners' line and the lower ones below."""
    head, _, _, _, lm = take
    assert not np.array_equal(lm[36:48], head.landmarks[36:48])  # open eyes: iBUG's differ
    rest = head.vertices[:, :2]
    for inner, outer, upper, lower in ((42, 45, (43, 44), (47, 46)), (39, 36, (38, 37), (40, 41))):
        c_in, c_out = rest[lm[inner]], rest[lm[outer]]
        length = np.linalg.norm(c_out - c_in)
        axis = (c_out - c_in) / length
        up = np.array([-axis[1], axis[0]]) * np.sign(axis[0])  # across the axis, upwards
        for k, frac in enumerate((1 / 3, 2 / 3)):
            for idx, sign in ((upper[k], 1.0), (lower[k], -1.0)):
                rel = rest[lm[idx]] - c_in
                assert abs(rel @ axis / length - frac) < 0.05
                assert sign * (rel @ up) > 2.0


def test_brows_end_to_end_on_the_middle_line(take):
    """Five points per brow on its middle line, the first and last at its ends."""
    head, vertices, _, _, lm = take
    from scan2morph.synth.shape import _Shape

    shape = _Shape(head.identity)
    rest = head.vertices[lm[17:27]]
    inner, outer = BROW_ENDS_MM
    np.testing.assert_allclose(np.abs(rest[[0, 9], 0]), outer, atol=1.5)
    np.testing.assert_allclose(np.abs(rest[[4, 5], 0]), inner, atol=1.5)
    middle = shape.brow_line(np.abs(rest[:, 0]))[0]
    np.testing.assert_allclose(rest[:, 1], middle, atol=1.0)
