"""Mesh and RGB-D takes end to end (issue #18): two tiny synthetic subjects, one of mesh scans and
one of RGB-D takes of two depth frames each (a neutral and a viseme each), run through the
workflow to their accuracy reports, and the stores record each take's modality and camera."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from scan2morph.store import load_layout, paths, validate_store
from tests.support.workflow_api import REPO, run_synthetic

pytestmark = pytest.mark.slow

TAKES = [
    dict(take="neutral", kind="neutral", label="neutral"),
    dict(take="car", kind="viseme", label="car"),
]
# two depth frames per RGB-D take, the head moving between them: the ingest fuses them
SENSOR = dict(
    width=160,
    height=120,
    focal_px=250.0,
    color_width=160,
    color_height=120,
    color_focal_px=258.0,
    frames=2,
)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    work = tmp_path_factory.mktemp("modalities")
    synthetic = dict(
        subjects=2,
        takes=TAKES,
        stereo=dict(subjects=[]),
        mesh=dict(subjects=[1], takes=["neutral", "car"]),
        rgbd=dict(subjects=[2], takes=["neutral", "car"], sensor=SENSOR),
    )
    targets = [f"results/{s}/accuracy.json" for s in ("synth01", "synth02")]
    assert run_synthetic(
        work,
        synthetic,
        targets,
        mesh_camera=dict(width=160, height=120),
        # an absolute alignment gate: repair smooths the RGB-D depth noise, so the meshes look
        # smoother (their roughness ~0.03 mm) than they are against each other (~0.2 mm)
        align=dict(icp=dict(max_rmse_mm=0.5)),
        modal=dict(modes=10, reconstruction_k=[1, 2, 5, 10]),
    )
    return work


@pytest.mark.parametrize(
    "subject, modality, rms_mm",
    [("synth01", "mesh", 0.3), ("synth02", "rgbd", 1.0)],  # 0.1 mm mesh noise; ~0.7 mm depth noise
)
def test_accuracy_by_modality(run, subject, modality, rms_mm):
    acc = json.loads((run / "results" / subject / "accuracy.json").read_text())
    assert [t["modality"] for t in acc["takes"].values()] == [modality, modality]
    by = acc["summary"]["by_modality"]
    print(f"\n{subject}: " + json.dumps(by))
    assert list(by) == [modality] and by[modality]["takes"] == ["neutral", "car"]
    assert by[modality]["mesh_rms_mm_max"] < rms_mm
    assert by[modality]["align_rotation_deg_max"] < 1.0
    assert by[modality]["align_translation_mm_max"] < 1.0
    assert by[modality]["motion_relative_error_max"] < 0.35
    if modality == "rgbd":
        assert by[modality]["depth_rms_mm_max"] < 2.0 and by[modality]["coverage_min"] > 0.6
    # no take left out of the models (a folded triangle or two in the fit of a 160 x 120 take
    # with its mouth open is a warning of its own, and allowed here)
    assert not [w for w in acc["warnings"] if not w.startswith("[fit]")]


def test_stores_record_modality_and_camera(run):
    layout = load_layout(REPO / "schemas" / "store.layout.yaml")
    for subject, modality in (("synth01", "mesh"), ("synth02", "rgbd")):
        store = run / "results" / subject / f"{subject}.h5"
        assert validate_store(store, layout) == []
        with h5py.File(store) as h5:
            for take in ("neutral", "car"):
                assert h5[paths.camera(take, "modality")].asstr()[()] == modality
                K = h5[paths.camera(take, "K")][()]
                assert K.shape == (3, 3) and K[2, 2] == 1.0
                assert h5[paths.camera(take, "size")][()].tolist() == [160, 120]
            if modality == "rgbd":  # the colour camera, 15 mm beside the depth camera
                attrs = h5[paths.take("car")].attrs
                assert attrs["depth_frames"] == 2  # registered (a small motion) and averaged
                assert 0.0 < attrs["depth_frame_motion_deg"][1] < 3.0
                assert len(attrs["input_sha256_depth"].split(";")) == 2
                assert h5[paths.camera("car", "K")][0, 0] == 258.0
                assert np.isclose(h5[paths.camera("car", "pose")][0, 3], -15.0)
