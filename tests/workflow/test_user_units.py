"""A user's mesh scan in another unit, through the workflow's subject check: the sheet's
``units`` column reaches the check (which sizes a mesh without landmarks), and a mesh without it
stops its subject with one line naming the unit it looks like.

The real head's GLB (in a unit of its own, 41.44 mm) was refused with ``units: 41.44`` until the
check job received each row's units.
"""

from __future__ import annotations

import json

import pytest
import trimesh
import yaml

from scan2morph.jobs import sha256_file
from scan2morph.synth.mesh_scan import make_mesh_take
from tests.support.workflow_api import run_workflow

pytestmark = pytest.mark.slow


def test_a_mesh_in_cm_passes_the_check_with_its_unit_and_stops_its_subject_without(tmp_path):
    scan = make_mesh_take("s1", "neutral", "neutral", "neutral", seed=3)
    colours = trimesh.visual.ColorVisuals(vertex_colors=scan["colors"])
    mesh = trimesh.Trimesh(scan["vertices"] / 10.0, scan["faces"], visual=colours, process=False)
    mesh.export(tmp_path / "head_cm.ply")
    header = ["subject", "take", "kind", "label", "modality", "mesh", "units"]
    rows = [
        ["given", "neutral", "neutral", "neutral", "mesh", "head_cm.ply", "cm"],
        ["given_as_number", "neutral", "neutral", "neutral", "mesh", "head_cm.ply", "10"],
        ["missing", "neutral", "neutral", "neutral", "mesh", "head_cm.ply", ""],
    ]
    sheet = tmp_path / "subjects.tsv"
    sheet.write_text("\n".join("\t".join(r) for r in [header, *rows]) + "\n")
    config = tmp_path / "my.yaml"
    config.write_text(yaml.safe_dump({"subjects": str(sheet), "synthetic": {"subjects": 0}}))
    targets = [f"results/{s}/check.json" for s in ("given", "given_as_number", "missing")]
    assert not run_workflow(tmp_path, config, targets)  # the subject without its unit stops
    for subject in ("given", "given_as_number"):
        report = json.loads((tmp_path / "results" / subject / "check.json").read_text())
        files = report.pop("files")  # the checksums of the files each verdict was found on
        assert report == {"subject": subject, "problems": [], "takes": {}}
        assert files == {"neutral": {"mesh": [sha256_file(tmp_path / "head_cm.ply")]}}
    assert not (tmp_path / "results" / "missing" / "check.json").exists()
    log = (tmp_path / "logs" / "check_subject" / "missing.log").read_text()
    assert "head_cm.ply: mesh size: " in log
    assert "(it looks like cm: give its unit in the sheet's units column" in log
