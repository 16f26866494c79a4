"""Every iBUG-68 table of the template against the iBUG-68 definition, and the synthetic
generator's landmarks against the template.

The oracle is the annotation scheme itself: each contour's points in order (jaw 1-17, brows
18-22 and 23-27, nose bridge 28-31, nose bottom 32-36, eyes 37-42 and 43-48, outer lips 49-60
and inner lips 61-68 as closed loops). Seen in an image (x right, y down), an open contour runs
monotonically along its chord and a closed loop turns once, clockwise, about its centroid (iBUG
goes along the top from the image's left, then back along the bottom). A point swapped with a
non-adjacent one of its contour breaks either rule.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from scan2morph.synth import cohort
from scan2morph.synth.head import LABEL_COEFFS, articulate, build_head
from scan2morph.template import build_template, load_template, save_template, subdivide_template
from scan2morph.template.mesh import FIDUCIAL_SETS, IBUG_CANONICAL, NAMED_POINTS
from scan2morph.template.regions import INNER_LIP_ROWS, LIP_BORDERS

#: The iBUG-68 contours (1-based numbers, in annotation order) and whether each is a closed loop.
CONTOURS = {
    "jaw": (tuple(range(1, 18)), False),
    "brow_r": (tuple(range(18, 23)), False),
    "brow_l": (tuple(range(23, 28)), False),
    "nose_bridge": (tuple(range(28, 32)), False),
    "nose_bottom": (tuple(range(32, 37)), False),
    "eye_r": (tuple(range(37, 43)), True),
    "eye_l": (tuple(range(43, 49)), True),
    "outer_lips": (tuple(range(49, 61)), True),
    "inner_lips": (tuple(range(61, 69)), True),
}


def _contour_problem(xy: np.ndarray, numbers: tuple[int, ...], closed: bool) -> str | None:
    """Why the points ``xy`` (68, 2) of one contour (image frame, y down) are out of order,
    or None."""
    p = xy[np.asarray(numbers) - 1]
    if not closed:
        along = (p - p[0]) @ (p[-1] - p[0])
        steps = np.diff(along)
        return None if (steps > 0).all() else f"not monotone along its chord: {steps.round(3)}"
    rel = p - p.mean(axis=0)
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    turn = np.angle(np.exp(1j * (np.roll(ang, -1) - ang)))  # wrapped steps, closing one too
    if (turn > 0).all() and np.isclose(turn.sum(), 2 * np.pi):
        return None
    return f"does not turn once clockwise: steps {np.degrees(turn).round(0)} degrees"


def _problems(xy: np.ndarray, skip=()) -> dict[str, str]:
    out = {}
    for name, (numbers, closed) in CONTOURS.items():
        if name not in skip and (why := _contour_problem(xy, numbers, closed)):
            out[name] = why
    return out


def _vertex_ibug(template) -> np.ndarray:
    """(68, 2) positions of the template vertices named ibugNN (NaN for the jaw but 9)."""
    xy = np.full((68, 2), np.nan)
    ok = template.ibug_vertex >= 0
    xy[ok] = template.vertices[template.ibug_vertex[ok]]
    return xy


def test_the_contour_check_sees_a_swap():
    assert _problems(IBUG_CANONICAL) == {}
    for a, b in ((56, 57), (50, 51), (38, 39), (62, 68), (44, 48), (3, 4)):
        swapped = IBUG_CANONICAL.copy()
        swapped[[a - 1, b - 1]] = swapped[[b - 1, a - 1]]
        assert _problems(swapped), (a, b)


@pytest.mark.parametrize("level", [0, 1, 2])
def test_template_vertices_named_ibug_follow_the_ibug_contours(tmp_path, level):
    base = build_template()
    save_template(tmp_path / "t.npz", base)
    for template in (
        subdivide_template(base, level),
        subdivide_template(load_template(tmp_path / "t.npz"), level),
    ):
        xy = _vertex_ibug(template)
        numbers = np.flatnonzero(template.ibug_vertex >= 0) + 1
        assert numbers.tolist() == [9, *range(18, 69)]
        np.testing.assert_allclose(xy[numbers - 1], IBUG_CANONICAL[numbers - 1], atol=1e-12)
        assert _problems(xy, skip=("jaw",)) == {}
        # the mouth hole's loop is the inner-lip contour, starting at 61
        mouth = template.ibug_vertex[60:68]
        i = int(np.flatnonzero(template.mouth_boundary == mouth[0])[0])
        loop = np.roll(template.mouth_boundary, -i)
        assert set(mouth) <= set(loop.tolist())
        assert np.all(np.diff(np.flatnonzero(np.isin(loop, mouth))) > 0)  # in iBUG order
        assert template.boundary[0] == template.ibug_vertex[8]  # the outline starts at the chin


def test_named_points_and_lip_tables_follow_ibug():
    t = build_template()
    for name, n in NAMED_POINTS.items():
        if isinstance(n, int):
            assert t.named[name] == t.ibug_vertex[n - 1]
        x = t.vertices[t.named[name], 0]
        # _r is the subject's right: the image's left (x < 0)
        if name.endswith("_r") or "_r_" in name:
            assert x < 0, name
        if name.endswith("_l") or "_l_" in name:
            assert x > 0, name
    for name, numbers in FIDUCIAL_SETS.items():
        assert t.fiducials[name][0].tolist() == list(numbers)
        np.testing.assert_allclose(
            t.vertices[t.fiducials[name][1]], IBUG_CANONICAL[np.array(numbers) - 1], atol=1e-12
        )
    # the vermilion borders: the outer-lip loop cut at its corners 49 and 55
    outer = list(CONTOURS["outer_lips"][0])
    assert (LIP_BORDERS["upper"] + 1).tolist() == outer[: outer.index(55) + 1]
    assert (LIP_BORDERS["lower"] + 1).tolist() == outer[outer.index(55) :] + [49]
    assert (INNER_LIP_ROWS + 1).tolist() == list(CONTOURS["inner_lips"][0])
    # and each border runs from corner to corner monotonically in x
    for side, sign in (("upper", 1), ("lower", -1)):
        assert (sign * np.diff(IBUG_CANONICAL[LIP_BORDERS[side], 0]) > 0).all(), side


def _procrustes(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``p`` (n, 2) moved onto ``q`` (n, 2) by the least-squares similarity (no mirror)."""
    pc, qc = p - p.mean(axis=0), q - q.mean(axis=0)
    u, s, vt = np.linalg.svd(pc.T @ qc)
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    return (np.diag(d) * s).sum() / (pc**2).sum() * pc @ (u @ d @ vt) + q.mean(axis=0)


@pytest.mark.parametrize("subject", ["s1", "s2"])
def test_synthetic_landmarks_agree_with_the_template(subject):
    """The generator's landmarks (mouth open, so that the inner lips are apart) seen from the
    front follow the contours, and each contour, moved onto the template's by a similarity,
    pairs every point with its own number (optimal assignment)."""
    head = build_head(cohort.subject_identity(subject, 3))
    verts = articulate(head, LABEL_COEFFS["car"])
    xy = verts[head.landmarks, :2] * np.array([1.0, -1.0])  # head frame y up -> image y down
    assert _problems(xy) == {}
    for name, (numbers, _) in CONTOURS.items():
        rows = np.asarray(numbers) - 1
        moved = _procrustes(xy[rows], IBUG_CANONICAL[rows])
        cost = np.linalg.norm(moved[:, None] - IBUG_CANONICAL[rows][None], axis=2)
        pairs = linear_sum_assignment(cost)[1]
        assert (pairs == np.arange(len(rows))).all(), (name, (rows[pairs] + 1).tolist())
