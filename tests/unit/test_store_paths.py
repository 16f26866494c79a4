"""The store path builders against the layout file (schemas/store.layout.yaml)."""

import re
from pathlib import Path

import pytest

from scan2morph.store import load_layout, paths

LAYOUT = Path(__file__).resolve().parents[2] / "schemas" / "store.layout.yaml"


def test_datasets_are_the_layout():
    layout = {e["path"] for e in load_layout(LAYOUT)["datasets"]}
    ours = {p for p in paths.DATASETS if not p.startswith(paths.PART_ONLY)}
    assert ours == layout


def test_every_stage_writes_something_and_stages_are_known():
    assert set(paths.DATASETS.values()) == set(paths.STAGES)


@pytest.mark.parametrize(
    ("built", "expected"),
    [
        (paths.mesh("car_2", "vertices"), "/takes/car_2/mesh/vertices"),
        (paths.range_image("n", "xyz"), "/takes/n/range/xyz"),
        (paths.raw("n", "color"), "/takes/n/raw/color"),
        (paths.landmarks("n"), "/takes/n/landmarks"),
        (paths.align("car", "transform"), "/takes/car/align/transform"),
        (paths.template("fiducials/names"), "/template/fiducials/names"),
        (paths.viseme("car", "noise_rms_mm"), "/visemes/car/noise_rms_mm"),
        (paths.expression("smile", "coordinates"), "/expressions/smile/coordinates"),
        (paths.modal_statistics("smile", "std"), "/modal/statistics/smile/std"),
        (paths.blend("open"), "/blends/open/vertices"),
        (paths.motion_noise("relative"), "/motion_noise/relative"),
    ],
)
def test_builders(built, expected):
    assert built == expected


def test_unknown_dataset_is_refused():
    with pytest.raises(KeyError, match="no dataset 'vertex'"):
        paths.mesh("car", "vertex")
    with pytest.raises(KeyError, match="unknown stages"):
        paths.written_by(["fitting"])


def test_written_by_splits_the_layout_by_stage():
    rx = paths.written_by(["align", "motion"])
    assert rx.match("/takes/car/align/vertices")
    assert rx.match("/expressions/smile/displacement")
    assert not rx.match("/expressions/smile/coordinates")  # modal
    assert not rx.match("/takes/car/mesh/vertices")  # fit
    assert not rx.match("/visemes/car/noise_rms_mm")  # motion_noise
    # each layout pattern is written by exactly one stage
    for pattern, stage in paths.DATASETS.items():
        example = re.sub(r"\{[a-z_]+\}", "x", pattern)
        hits = [s for s in paths.STAGES if paths.written_by([s]).match(example)]
        assert hits == [stage], pattern


def test_ids_in_key_order():
    keys = ["/takes/b/mesh/vertices", "/takes/a/mesh/vertices", "/takes/a/mesh/uv", "/takes/c/x"]
    assert paths.ids(keys, paths.TAKES, "mesh/vertices") == ["b", "a"]


def test_every_layout_dataset_has_units_and_a_description():
    """What describe_store writes onto each dataset of a store (text for HDF5 viewers)."""
    for entry in load_layout(LAYOUT)["datasets"]:
        assert isinstance(entry.get("units"), str), entry["path"]
        assert entry.get("description", "").strip(), entry["path"]
