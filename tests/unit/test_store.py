"""The HDF5 store: parts, merge, version check, layout validation."""

from __future__ import annotations

import io
import json
import os
import stat
from pathlib import Path

import h5py
import numpy as np
import pytest

from scan2morph import __version__
from scan2morph.errors import InputError
from scan2morph.provenance import run_provenance
from scan2morph.store import (
    FORMAT_VERSION,
    load_layout,
    merge_parts,
    open_store,
    read_part,
    validate_store,
    write_part,
)

LAYOUT = Path(__file__).resolve().parents[2] / "schemas" / "store.layout.yaml"


def _range_layout():
    """The layout's entries for the repaired range data (what these tests' parts write)."""
    layout = load_layout(LAYOUT)
    layout["datasets"] = [
        d
        for d in layout["datasets"]
        if d["path"].startswith("/takes/{take}/range/") or d["path"].endswith("landmarks")
    ]
    assert len(layout["datasets"]) == 5
    return layout


def _take_part(path, take, h=4, w=5):
    rng = np.random.default_rng(len(take))
    g = f"/takes/{take}"
    write_part(
        path,
        {
            f"{g}/range/xyz": rng.normal(size=(h, w, 3)).astype(np.float32),
            f"{g}/range/color": rng.integers(0, 255, (h, w, 3), dtype=np.uint8),
            f"{g}/range/spikes": np.zeros((h, w), bool),
            f"{g}/range/filled": np.zeros((h, w), bool),
            f"{g}/landmarks": rng.uniform(0, 4, (68, 2)),
        },
        attrs={g: {"kind": "viseme", "input_sha256_xyz": "ab" * 32, "repair": {"n_holes": 2}}},
    )


def test_merge_and_validate(tmp_path):
    _take_part(tmp_path / "a.h5", "neutral")
    _take_part(tmp_path / "b.h5", "car", h=6, w=7)  # takes may differ in image size
    out = tmp_path / "s" / "s.h5"
    provenance = run_provenance("ef" * 32)
    merge_parts(out, [tmp_path / "a.h5", tmp_path / "b.h5"], "s", "cd" * 32, (), provenance)
    assert validate_store(out, _range_layout()) == []
    with open_store(out) as h5:
        assert h5.attrs["format_version"] == FORMAT_VERSION
        assert h5.attrs["code_sha256"] == "ef" * 32
        assert h5.attrs["scan2morph_version"] == __version__
        assert h5.attrs["subject"] == "s"
        assert json.loads(h5.attrs["input_sha256"]) == {
            "car": {"xyz": "ab" * 32},
            "neutral": {"xyz": "ab" * 32},
        }
        assert json.loads(h5["takes/car"].attrs["repair"]) == {"n_holes": 2}
        assert h5["takes/car/range/xyz"].shape == (6, 7, 3)
    data = read_part(out, "/takes/car")
    assert data["/takes/car/landmarks"].shape == (68, 2)


def test_layout_validation_finds_problems(tmp_path):
    _take_part(tmp_path / "a.h5", "neutral")
    with h5py.File(tmp_path / "a.h5", "a") as h5:
        del h5["takes/neutral/range/filled"]
        del h5["takes/neutral/landmarks"]
        h5["takes/neutral/landmarks"] = np.zeros((67, 2))
    out = tmp_path / "s.h5"
    merge_parts(out, [tmp_path / "a.h5"], "s", "0" * 64)
    problems = validate_store(out, _range_layout())
    assert "/takes/neutral/range/filled: required dataset missing" in problems
    assert any("/takes/neutral/landmarks: shape (67, 2)" in p for p in problems)


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o027, 0o640)])
def test_parts_and_stores_honour_the_umask(tmp_path, umask, mode):
    """Written as any new file is (issue #19: the atomic write's temporary kept mode 0600)."""
    old = os.umask(umask)
    try:
        _take_part(tmp_path / "a.h5", "neutral")
        merge_parts(tmp_path / "s" / "s.h5", [tmp_path / "a.h5"], "s", "0")
        _take_part(tmp_path / "a.h5", "car")  # replacing a file gives the same mode
    finally:
        os.umask(old)
    for path in (tmp_path / "a.h5", tmp_path / "s" / "s.h5"):
        assert stat.S_IMODE(path.stat().st_mode) == mode, path
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a.h5", "s", "s.h5"]


def test_two_parts_writing_one_dataset_is_an_error(tmp_path):
    _take_part(tmp_path / "a.h5", "neutral")
    _take_part(tmp_path / "b.h5", "neutral")
    with pytest.raises(InputError, match="two parts write it"):
        merge_parts(tmp_path / "s.h5", [tmp_path / "a.h5", tmp_path / "b.h5"], "s", "0")
    assert not (tmp_path / "s.h5").exists()
    assert list(tmp_path.glob("*.tmp")) == []


def test_open_store_refuses_unknown_major(tmp_path):
    _take_part(tmp_path / "a.h5", "neutral")
    out = tmp_path / "s.h5"
    merge_parts(out, [tmp_path / "a.h5"], "s", "0")
    with h5py.File(out, "a") as h5:
        h5.attrs["format_version"] = "2.0.0"
    with pytest.raises(InputError, match=r"format_version 2.0.0 is not readable .*\(reads 1.x\)"):
        open_store(out)
    with h5py.File(out, "a") as h5:
        del h5.attrs["format_version"]
    with pytest.raises(InputError, match="'format_version' missing"):
        open_store(out)
    (tmp_path / "x.h5").write_text("nope")
    with pytest.raises(InputError, match="not an HDF5 file"):
        open_store(tmp_path / "x.h5")


def test_read_attrs_of_a_group_a_part_lacks(tmp_path):
    """A group's attributes as written; a group the part lacks is an error, or ``{}`` when the
    caller allows it (a left-out take's refine part has no refine group)."""
    from scan2morph.store.hdf5 import read_attrs, write_part

    part = tmp_path / "refine.h5"
    write_part(
        part,
        {"takes/car/refine/valid": np.ones(3, bool)},
        attrs={"takes/car/refine": {"shape_used": 1.0, "problem": "x"}},
    )
    assert read_attrs(part, "takes/car/refine") == {"shape_used": 1.0, "problem": "x"}
    assert read_attrs(part, "takes/too/refine", missing_ok=True) == {}
    with pytest.raises(KeyError):
        read_attrs(part, "takes/too/refine")


def test_the_layout_names_the_format_it_describes():
    """The layout file is the stores' contract: its own format_version is the one the stores
    are written with (it said 1.4.0 while the stores were 1.8.0)."""
    from scan2morph.store import load_layout
    from tests.support.workflow_api import REPO

    layout = load_layout(REPO / "schemas" / "store.layout.yaml")
    assert layout["format_version"] == FORMAT_VERSION


def test_the_store_says_which_code_made_it(tmp_path):
    """The store stage writes the code fingerprint of the stages that made it (the workflow's,
    or its own without one), the git commit of the checkout (with whether it was dirty) and the
    dependencies' versions; every root attribute it writes is one the layout names."""
    from scan2morph.provenance import git_state
    from scan2morph.stages import Subject, store
    from scan2morph.stages.stage_job import code_fingerprints

    write_part(tmp_path / "a.h5", {"/template/faces": np.zeros((1, 3), np.int64)})
    layout = _range_layout()
    params = store.Params.from_config({"quality": {}}).with_layout(layout)
    subject = Subject("s", {"neutral": "neutral"}, {"neutral": "neutral"})
    given = store.run(
        None, subject, {"parts": [tmp_path / "a.h5"], "code_sha256": "ab" * 32}, params
    )
    own = store.run(None, subject, {"parts": [tmp_path / "a.h5"]}, params)
    for part, code in ((given, "ab" * 32), (own, code_fingerprints(["store"])["store"])):
        with h5py.File(io.BytesIO(part.files["store"]), "r") as h5:
            attrs = dict(h5.attrs)
        assert attrs["code_sha256"] == code
        assert json.loads(attrs["dependencies"])["numpy"] == np.__version__
        assert {k: attrs.get(k) for k in git_state()} == git_state()  # absent outside git
        named = {*layout["root_attributes"], *layout["optional_root_attributes"]}
        assert set(attrs) <= named
        assert set(layout["root_attributes"]) <= set(attrs)


def test_the_layout_says_the_expression_displacement_is_smoothed():
    """Every store carries the layout's description as the dataset's ``description`` attribute.
    The motion stage smooths expression fields (``smoothing.expression_iterations`` Laplacian
    steps, 10 by default) since 2026-12-02; the layout still said "neither masked nor smoothed"."""
    import yaml

    from tests.support.workflow_api import REPO

    (entry,) = [
        d
        for d in load_layout(LAYOUT)["datasets"]
        if d["path"] == "/expressions/{take}/displacement"
    ]
    text = " ".join(entry["description"].split())
    assert "nor smoothed" not in text and "not smoothed" not in text
    assert "smoothed by smoothing.expression_iterations" in text
    schema = yaml.safe_load((REPO / "schemas" / "config.schema.yaml").read_text(encoding="utf-8"))
    default = schema["properties"]["smoothing"]["properties"]["expression_iterations"]["default"]
    assert f"({default} by default" in text


def test_the_modal_physics_reads_alike_from_a_file_and_a_mapping(tmp_path):
    """One reader of /modal/physics for the figures and the report (the review: two copies, the
    report's crashing on a value that is not JSON)."""
    import json

    import h5py

    from scan2morph.store import paths
    from scan2morph.store.modal_physics import modal_physics, vertex_coordinates

    physics = {"coordinates": "vertex", "outline_strip_mm": 6.0}
    key = paths.modal("physics")
    with h5py.File(tmp_path / "s.h5", "w") as h5:
        h5[key] = json.dumps(physics)
    with h5py.File(tmp_path / "s.h5") as h5:
        assert modal_physics(h5) == physics and vertex_coordinates(h5)
        assert modal_physics(read_part(tmp_path / "s.h5")) == physics
    assert modal_physics({key: np.array(json.dumps(physics).encode())}) == physics
    assert modal_physics({}) == {} and not vertex_coordinates({})
    assert modal_physics({key: "not json"}) == {} and modal_physics({key: "[1, 2]"}) == {}
    assert not vertex_coordinates({key: json.dumps({"coordinates": "mass"})})
