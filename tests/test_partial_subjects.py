"""Subjects with only some takes: every stage whose inputs exist runs, the others are skipped
and say so in the store and the report (end to end, through the workflow)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import yaml

from scan2morph.io import read_glb_targets
from scan2morph.stages.quality import read_warnings, skipped_stages
from scan2morph.store import load_layout, paths, validate_store
from scan2morph.synth import make_take, write_take
from scan2morph.tables import read_table
from tests.workflow_api import REPO, run_workflow

pytestmark = pytest.mark.slow

TINY = dict(width=160, height=120, focal_px=362.5, distance_mm=1000.0)
HEADER = "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor\tleft\tright\tcalibration\tlandmarks\n"
#: subject -> its takes (take, kind, label): neutral only, neutral + expressions, one viseme.
SUBJECTS = {
    "solo": [("neutral", "neutral", "neutral")],
    "expr": [("neutral", "neutral", "neutral"), ("smile1", "expression", "smile")],
    "one": [("neutral", "neutral", "neutral"), ("car", "viseme", "car")],
}


@pytest.fixture(scope="module")
def partial(tmp_path_factory):
    work = tmp_path_factory.mktemp("partial")
    rows = []
    for subject, takes in SUBJECTS.items():
        d = work / "scans" / subject
        d.mkdir(parents=True)
        for take, kind, label in takes:
            res = make_take("person", label, kind, take, seed=11, params=dict(TINY))
            write_take(res, d / f"{take}.abs.gz", d / f"{take}.png", d / f"{take}.pts", d / "t.npz")
            files = [f"{subject}/{take}.abs.gz", f"{subject}/{take}.png", "", "", ""]
            rows.append([subject, take, kind, label, "range", *files, f"{subject}/{take}.pts"])
    sheet = work / "scans" / "subjects.tsv"
    sheet.write_text(HEADER + "".join("\t".join(r) + "\n" for r in rows))
    cfg = dict(subjects=str(sheet), synthetic=dict(subjects=0), modal=dict(modes=10))
    configfile = work / "partial.yaml"
    configfile.write_text(yaml.safe_dump(cfg))
    targets = [f"results/{s}/report.html" for s in SUBJECTS] + ["results/cohort/summary.tsv"]
    assert run_workflow(work, configfile, targets=targets, keep_going=False)
    return work


def _store(work, subject):
    return work / "results" / subject / f"{subject}.h5"


def test_every_shape_of_subject_gets_a_valid_store(partial):
    layout = load_layout(REPO / "schemas" / "store.layout.yaml")
    for subject in SUBJECTS:
        assert validate_store(_store(partial, subject), layout) == [], subject
        with h5py.File(_store(partial, subject)) as h5:
            assert h5[paths.modal("modes")].shape[0] == 10  # every subject gets a modal basis
            assert read_warnings(h5) == []


def test_neutral_only_subject(partial):
    with h5py.File(_store(partial, "solo")) as h5:
        assert paths.PCA not in h5 and paths.VISEMES not in h5
        skipped = skipped_stages(h5)
    assert skipped["morph"].startswith("no viseme takes")
    assert skipped["modal_coordinates"].startswith("no expression takes")
    assert skipped["motion_noise"].startswith("no viseme takes")
    # the glTF holds the textured neutral alone; the PCA tables are empty but present
    base, targets = read_glb_targets(partial / "results" / "solo" / "solo.glb")
    assert targets == {} and np.isfinite(base).all()
    tables = partial / "results" / "solo" / "tables"
    eigen = read_table(tables / "pca_eigenvalues.tsv")
    assert len(eigen) == 0 and eigen.columns[:4].tolist() == [
        "component",
        "eigenvalue",
        "cr",
        "ccr",
    ]
    html = (partial / "results" / "solo" / "report.html").read_text()
    assert "no viseme takes: no blend shapes or PCA" in html
    assert "Warnings and skipped stages" in html


def test_neutral_and_expressions_get_modal_coordinates(partial):
    with h5py.File(_store(partial, "expr")) as h5:
        q = h5[paths.expression("smile1", "coordinates")][()]
        assert q.shape == (10,) and np.isfinite(q).all() and np.abs(q).max() > 0
        assert paths.PCA not in h5
        assert "modal_coordinates" not in skipped_stages(h5)


def test_one_viseme_gives_blends_and_a_pca_of_two_shapes(partial):
    with h5py.File(_store(partial, "one")) as h5:
        assert list(h5[paths.pca("takes")].asstr()[()]) == ["neutral", "car"]
        assert h5[paths.pca("eigenvalues")].shape == (1,)
        assert paths.blend("car_60") in h5
        assert skipped_stages(h5) == {
            "modal_coordinates": "no expression takes: the modal basis only, no modal coordinates"
        }
    _, targets = read_glb_targets(partial / "results" / "one" / "one.glb")
    assert set(targets) == {"car", "pca_mean", "pca_1"}
