"""Store comparison (reproducibility checks) on small parts with known differences."""

import json

import numpy as np

from scan2morph.store import write_part
from scan2morph.store.compare import main, store_differences


def _pair(tmp_path, b_data, b_attrs=None):
    a_data = {
        "/x/v": np.array([[1.0, np.nan], [3.0, 4.0]]),
        "/x/names": ["a", "b"],
        "/k": np.int64(3),
    }
    a_attrs = {
        "/": {"config_sha256": "aaa", "subject": "s"},
        "/x": {"fit": 0.5, "stereo": json.dumps({"timings_s": {"sgbm": 1.0}, "n": 5})},
    }
    write_part(tmp_path / "a.h5", a_data, attrs=a_attrs)
    write_part(tmp_path / "b.h5", a_data | b_data, attrs=b_attrs or a_attrs)
    return tmp_path / "a.h5", tmp_path / "b.h5"


def test_equal_up_to_tolerance_and_provenance(tmp_path):
    attrs = {
        "/": {"config_sha256": "bbb", "subject": "s"},  # a run attribute: not compared
        "/x": {"fit": 0.5, "stereo": json.dumps({"timings_s": {"sgbm": 9.0}, "n": 5})},
    }
    a, b = _pair(tmp_path, {"/x/v": np.array([[1.0 + 1e-13, np.nan], [3.0, 4.0]])}, attrs)
    assert store_differences(a, b) == []
    assert main([str(a), str(b)]) == 0


def test_every_kind_of_difference_is_named(tmp_path, capsys):
    attrs = {
        "/": {"config_sha256": "aaa", "subject": "t"},
        "/x": {"fit": 0.75, "stereo": json.dumps({"timings_s": {}, "n": 6})},
    }
    b_data = {
        "/x/v": np.array([[1.0, 2.0], [3.0, 4.5]]),
        "/x/names": ["a", "c"],
        "/k": np.zeros(2),
        "/extra": np.ones(1),
    }
    a, b = _pair(tmp_path, b_data, attrs)
    lines = store_differences(a, b)
    assert lines == [
        f"/extra: only in {b}",
        "/k: shape () != (2,)",
        "/x/names: values differ (object vs object)",
        "/x/v: NaN in different places",
        "/@subject: 's' != 't'",
        "/x@fit: max |difference| 0.25",
        "/x@stereo.n: '5' != '6'",
    ]
    assert main([str(a), str(b), "--atol", "1"]) == 1
    assert "/x/v" in capsys.readouterr().out


def test_relative_tolerance_of_each_element_or_of_the_array(tmp_path):
    # last-bit noise of 3e-12 on an entry near zero (1e-6) of a mode vector whose largest entry
    # is 0.01: within 1e-9 of the array's scale (1e-11), far beyond 1e-9 of the entry (1e-15)
    mode = np.array([0.01, -0.006, 1e-6])
    write_part(tmp_path / "a.h5", {"/m": mode})
    write_part(tmp_path / "b.h5", {"/m": mode + np.array([0.0, 0.0, 3e-12])})
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    assert store_differences(a, b, atol=0.0, rtol=1e-9) == ["/m: max |difference| 3e-12"]
    assert store_differences(a, b, atol=0.0, rtol=1e-9, scale="array") == []
    assert store_differences(a, b, atol=0.0, rtol=1e-10, scale="array") != []
    assert main([str(a), str(b), "--atol", "0", "--rtol", "1e-9", "--scale", "array"]) == 0
