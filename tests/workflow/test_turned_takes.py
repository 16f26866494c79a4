"""The real head's range takes turned 8 degrees of yaw from their neutral, without landmark files
(tests/support/turned_takes.py): the detector errs differently in the two views, and the
doubtful detection's upper face is carried from the neutral in the refinement (docs/methods.md).

Measured (benchmarks/bench_turned_takes.py, seeds 7 and 11), material error of the detected jaw
drop / smile: 0.157 / 0.449 and 0.171 / 0.299 (with landmark files 0.104 / 0.165 and
0.106 / 0.158); before the carry 0.222 / 2.001 and 0.235 / 2.220. Here (other noise: only
the variants 8 and 20 written) 0.178 / 0.298. The smile's bound tells the two apart; the jaw
drop's is a sanity check.

The same head's takes with their landmark files, turned 20 degrees from the neutral: the side
of the face the take sees more obliquely than the neutral was matched mm off (the benchmark,
seed 7: 0.849 of the smile's motion in error, 0.122 seen as the neutral is) and nothing warned;
that steep skin is now left to its neighbours (``refine.turned_view_deg``: 0.413; here 0.430,
the jaw drop 0.118) and the turn is a warning."""

from __future__ import annotations

import pytest

from scan2morph.store import read_part
from scan2morph.store.warnings import read_warnings
from tests.support.lps_landmarks import load_real_head
from tests.support.real_head import GLB
from tests.support.turned_takes import evaluate, write_takes
from tests.support.workflow_api import run_workflow

pytestmark = [
    pytest.mark.slow,
    pytest.mark.realdata,
    pytest.mark.skipif(not GLB.is_file(), reason=f"real head scan absent: {GLB}"),
]

#: Asserted bounds on the detected takes' material error (seed 7), 8 degrees turned.
BOUNDS = {"car1": 0.3, "smile1": 0.6}
#: ... and on the clicked takes', 20 degrees turned.
CLICKED_BOUNDS = {"car1": 0.2, "smile1": 0.6}


def test_takes_turned_from_their_neutral(tmp_path):
    head = load_real_head()
    poses = write_takes(head, tmp_path, seed=7, turns=(8.0, 20.0))
    subjects = ("yaw8_detected", "yaw20_clicked")
    targets = [f"results/{s}/{s}.h5" for s in subjects]
    assert run_workflow(tmp_path, tmp_path / "turned.yaml", targets)
    result = evaluate(head, tmp_path, subjects[0], poses)
    print(result)
    for take, bound in BOUNDS.items():
        r = result[take]
        assert "left_out" not in r, (take, r)
        assert "doubtful" in r["doubtful"], (take, r)  # the mechanism's trigger
        assert r["rotation_deg"] < 0.1 and r["vertices"] > 1600, (take, r)
        assert r["material_relative_error"] < bound, (take, r)
    result = evaluate(head, tmp_path, subjects[1], poses)
    print(result)
    for take, bound in CLICKED_BOUNDS.items():
        r = result[take]
        assert "left_out" not in r and not r["doubtful"], (take, r)
        assert r["rotation_deg"] < 0.1 and r["vertices"] > 1600, (take, r)
        assert r["material_relative_error"] < bound, (take, r)
    store = read_part(tmp_path / "results" / subjects[1] / f"{subjects[1]}.h5")
    turned = [w for w in read_warnings(store) if "degrees away from where its neutral" in w.message]
    assert [(w.stage, w.take) for w in turned] == [("align", "car1"), ("align", "smile1")]
    assert all(w.message.startswith("seen from 20 degrees away") for w in turned), turned
