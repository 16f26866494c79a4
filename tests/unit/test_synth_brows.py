"""The strong brow expressions of the synthetic cohort (brows, frown): they move the forehead."""

from __future__ import annotations

import numpy as np

from scan2morph.synth import cohort
from scan2morph.synth.articulation import LABEL_COEFFS, LABEL_KIND, label_coefficients
from scan2morph.synth.head import articulate, build_head

SEED = 3


def test_brow_raise_and_frown_move_the_brows_and_the_forehead_above():
    """brows: the inner brow ends (iBUG 22, 23) rise 5-8 mm, the forehead 25 mm above them
    follows by more than half, 50 mm above still by some; frown: the brows drop 3-6 mm and come
    together, the forehead above follows. A sad moves the forehead less (what it leaves still
    the alignment may take for still skin)."""
    head = build_head(cohort.subject_identity("s1", SEED))
    rest = head.vertices
    disp = {lab: articulate(head, LABEL_COEFFS[lab]) - rest for lab in ("brows", "frown", "sad")}
    inner = head.landmarks[[21, 22]]
    assert (disp["brows"][inner, 1] > 5.0).all() and (disp["brows"][inner, 1] < 8.0).all()
    assert (disp["frown"][inner, 1] < -3.0).all() and (disp["frown"][inner, 1] > -6.0).all()
    assert (np.sign(rest[inner, 0]) * disp["frown"][inner, 0] < -1.5).all()

    def above(i, mm):
        """The forehead vertex ``mm`` above vertex ``i`` (the frontmost within 3 mm in x, y)."""
        near = np.flatnonzero(
            (np.abs(rest[:, 0] - rest[i, 0]) < 3.0) & (np.abs(rest[:, 1] - rest[i, 1] - mm) < 3.0)
        )
        return near[np.argmax(rest[near, 2])]

    for i in inner:
        j25, j50 = above(i, 25.0), above(i, 50.0)
        assert disp["brows"][j25, 1] > 0.5 * disp["brows"][i, 1], disp["brows"][[i, j25]]
        assert disp["brows"][j50, 1] > 0.5, disp["brows"][j50]
        assert disp["frown"][j25, 1] < -0.5, disp["frown"][j25]
        assert disp["brows"][j25, 1] > 2.0 * disp["sad"][j25, 1], (disp["brows"][j25], disp["sad"])
    # the lower face: a brow raise comes with a slight sad mouth, the frown leaves it still
    chin = head.landmarks[8]
    assert np.abs(disp["frown"][chin]).max() < 1e-9
    assert np.abs(disp["frown"][head.landmarks[48:68]]).max() < 1e-9


def test_new_labels_are_expressions_with_one_intensity_draw_per_driver():
    assert LABEL_KIND["brows"] == LABEL_KIND["frown"] == "expression"
    # brows: the brow raise and the sad mouth each draw their own intensity
    a = label_coefficients("brows", np.random.default_rng(0))
    rng = np.random.default_rng(0)
    f1 = float(np.clip(1.0 + 0.08 * rng.standard_normal(), 0.8, 1.2))
    f2 = float(np.clip(1.0 + 0.08 * rng.standard_normal(), 0.8, 1.2))
    assert a == {"brow_raise": f1, "sad": 0.5 * f2}
    b = label_coefficients("frown", np.random.default_rng(0))
    assert b == {"frown": f1}
