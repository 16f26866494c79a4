"""Geometry-only mesh scans and the sheet's ``units`` column.

A mesh without texture or colours (as scanners and model-fitting datasets ship them) is rendered
grey, shaded from the camera; it runs through ingest, repair, fit and align, and the refinement
keeps the template fit with its reason. A mesh in metres with ``units: m`` gives the take of the
same mesh in mm.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh

from scan2morph.errors import InputError
from scan2morph.sheet import read_sheet, subject_problems
from scan2morph.stages import align, fit, ingest, landmarks, refine, repair
from scan2morph.stages.part import Run, Subject, Take
from scan2morph.store import paths
from scan2morph.synth.mesh_scan import make_mesh_take, write_landmarks3d
from scan2morph.template import build_template
from tests.support.configs import repo_config

CAMERA = {"width": 320, "height": 240}
KINDS = {"neutral": "neutral", "car": "viseme"}


def _run_ingest(row, files, mesh_camera=None):
    """The ingest stage on one take's files."""
    params = ingest.Params(mesh_camera=mesh_camera or {})
    return ingest.run(None, Take.from_row(row, files=files), params)


def _row(take: str, **extra) -> dict:
    return dict(subject="s1", take=take, kind=KINDS[take], label=take, modality="mesh") | extra


@pytest.fixture(scope="module")
def scans(tmp_path_factory):
    """The neutral and car of a synthetic subject as untextured OBJs (mm), its car also in
    metres and as the vertex-coloured PLY the generator writes."""
    d = tmp_path_factory.mktemp("geometry")
    out = {}
    for take in KINDS:
        r = make_mesh_take("s1", take, KINDS[take], take, seed=3)
        plain = trimesh.Trimesh(r["vertices"], r["faces"], process=False)
        plain.export(d / f"{take}.obj")
        write_landmarks3d(d / f"{take}.txt", r["landmarks"])
        out[take] = {"obj": d / f"{take}.obj", "landmarks": d / f"{take}.txt", "result": r}
    r = out["car"]["result"]
    trimesh.Trimesh(r["vertices"] / 1000.0, r["faces"], process=False).export(d / "car_m.obj")
    np.savetxt(d / "car_m.txt", r["landmarks"] / 1000.0, fmt="%.10f")  # 0.1 um
    coloured = trimesh.Trimesh(r["vertices"], r["faces"], vertex_colors=r["colors"], process=False)
    coloured.export(d / "car.ply")
    out["car"] |= {"obj_m": d / "car_m.obj", "landmarks_m": d / "car_m.txt", "ply": d / "car.ply"}
    return out


def _ingest(row: dict, mesh, landmarks):
    return _run_ingest(row, {"mesh": str(mesh), "landmarks": str(landmarks)}, CAMERA).datasets


class _Warnings(logging.Handler):
    """The scan2morph logger's warnings while it is attached."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())


@pytest.fixture(scope="module")
def plain(scans):
    """The neutral's and the car's untextured OBJs ingested once (read-only datasets, shared by
    the tests below) with the warnings each logged."""
    logger = logging.getLogger("scan2morph")
    level = logger.level
    out = {}
    for take in KINDS:
        warnings = _Warnings()
        logger.addHandler(warnings)
        logger.setLevel(logging.WARNING)
        try:
            data = _ingest(_row(take), scans[take]["obj"], scans[take]["landmarks"])
        finally:
            logger.removeHandler(warnings)
            logger.setLevel(level)
        for value in data.values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
        out[take] = (data, warnings.messages)
    return out


def test_an_untextured_mesh_is_shaded_fitted_and_keeps_its_fit_at_refine(scans, plain):
    data = {}
    for take in KINDS:
        data |= plain[take][0]
        assert any("texture-driven refinement is not available" in m for m in plain[take][1])
        assert data[paths.camera(take, "color_source")] == "shading"
        color = data[paths.raw(take, "color")]
        face = np.isfinite(data[paths.raw(take, "xyz")][..., 2])
        seen = color[face]
        assert (seen[:, 0] == seen[:, 1]).all() and (seen[:, 1] == seen[:, 2]).all()
        grey = seen[:, 0].astype(float)
        assert grey.std() > 15.0 and grey.max() > 200  # shaded, brightest where it faces us
    # the same geometry as the vertex-coloured scan of the car: the colour changes nothing else
    coloured = _ingest(_row("car"), scans["car"]["ply"], scans["car"]["landmarks"])
    assert coloured[paths.camera("car", "color_source")] == "vertex colours"
    a, b = coloured[paths.raw("car", "xyz")], data[paths.raw("car", "xyz")]
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    # mm: the depth buffer's resolution (the OBJ's 8 digits against the PLY's float32 move an edge)
    np.testing.assert_allclose(a, b, atol=0.03)

    config = repo_config()
    run = Run(Subject("s1", KINDS, {t: t for t in KINDS}), build_template(), config)
    for stage in (repair, landmarks, fit, align):
        data |= stage.apply(data, run)
    assert data[paths.mesh("car", "valid")].mean() > 0.9
    params = refine.Params.from_config(config)
    part = refine.run(run.template, Take.of(run.subject, "car", data=data), params)
    attrs = part.attrs[paths.refine_group("car")]
    assert not attrs["used"]
    assert attrs["problem"].startswith(
        "neutral and car are geometry-only scans (no texture or colours: rendered with shading): "
        "texture-driven refinement is not available, the template fit is kept"
    )
    assert not attrs["lip_used"] and "geometry-only" in attrs["lip_problem"]
    points = part.datasets[paths.refine("car", "points2d")]
    fitted = data[paths.mesh("car", "points2d")]
    # the fit's points, but where the jaw prior (geometry) moved the chin
    confidence = part.datasets[paths.refine("car", "confidence")]
    kept = confidence == 0
    assert kept.mean() > 0.8
    np.testing.assert_array_equal(points[kept], fitted[kept])


def test_a_mesh_in_metres_with_its_unit_equals_the_mesh_in_mm(scans, plain):
    car = scans["car"]
    mm = plain["car"][0]
    metres = _ingest(_row("car", units="m"), car["obj_m"], car["landmarks_m"])
    np.testing.assert_allclose(metres[paths.clicks("car")], mm[paths.clicks("car")], atol=1e-3)
    a, b = metres[paths.raw("car", "xyz")], mm[paths.raw("car", "xyz")]
    both = np.isfinite(a[..., 2]) & np.isfinite(b[..., 2])
    assert both.sum() > 0.99 * np.isfinite(b[..., 2]).sum()
    np.testing.assert_allclose(a[both], b[both], atol=0.03)  # mm: the depth buffer's resolution
    assert np.median(np.abs(a[both] - b[both])) < 1e-3
    # the unit as a number of mm per unit: the same scale, the same take bit for bit
    numeric = _ingest(_row("car", units="1000"), car["obj_m"], car["landmarks_m"])
    for key in (paths.clicks("car"), paths.raw("car", "xyz")):
        np.testing.assert_array_equal(numeric[key], metres[key])
    with pytest.raises(InputError, match="looks like metres, not mm: give its unit in the sheet"):
        _ingest(_row("car"), car["obj_m"], car["landmarks_m"])


def test_a_bad_unit_is_refused_naming_the_row_and_the_column(tmp_path, scans):
    car = scans["car"]
    header = "subject\ttake\tkind\tlabel\tmodality\tmesh\tlandmarks\tunits\n"
    rows = [
        f"s1\tneutral\tneutral\tneutral\tmesh\t{scans['neutral']['obj']}\t"
        f"{scans['neutral']['landmarks']}\t\n",
        f"s1\tcar\tviseme\tcar\tmesh\t{car['obj_m']}\t{car['landmarks_m']}\tinch\n",
        f"s1\tcar2\tviseme\tcar\tstereo\t\t{car['landmarks_m']}\tcm\n",
        f"s1\tcar3\tviseme\tcar\tmesh\t{car['obj_m']}\t{car['landmarks_m']}\t-2.5\n",
        f"s1\tcar4\tviseme\tcar\tmesh\t{car['obj_m']}\t{car['landmarks_m']}\t25.4\n",
    ]
    (tmp_path / "sheet.tsv").write_text(header + "".join(rows))
    table = read_sheet(tmp_path / "sheet.tsv")
    problems = subject_problems(table, check_files=False)["s1"]
    sheet = tmp_path / "sheet.tsv"
    expected = "(expected mm, cm, m or a number of mm per unit, e.g. 25.4 for inches; "
    assert f"{sheet} row 3 (s1/car): column 'units': 'inch' unknown {expected}" in (
        "\n".join(problems)
    )
    assert f"{sheet} row 5 (s1/car3): column 'units': '-2.5' unknown {expected}" in (
        "\n".join(problems)
    )
    assert not any("row 6 " in p and "units" in p for p in problems)  # 25.4 mm a unit (inches)
    assert any(
        p.startswith(f"{sheet} row 4 (s1/car2): column 'units': 'cm' is for mesh and range takes")
        for p in problems
    )
    assert not any("row 2 " in p for p in problems)  # empty: mm
    row = table.iloc[1].to_dict()
    with pytest.raises(InputError, match=r"row 3 \(s1/car\): column 'units': 'inch' unknown"):
        _run_ingest(row, {"mesh": row["mesh"], "landmarks": row["landmarks"]}, CAMERA)


def test_a_range_scan_without_colour_is_shaded_and_keeps_its_fit_at_refine(tmp_path, caplog):
    """A range take whose sheet row names no colour image: its grid shows its shading, the
    sheet and the check accept it, and the refinement keeps the template fit with its reason."""
    from scan2morph.io.check import take_file_problems
    from scan2morph.synth import make_take, write_take

    small = dict(width=320, height=240, focal_px=725.0, distance_mm=1000.0)
    data, files = {}, {}
    for take in KINDS:
        res = make_take("s1", take, KINDS[take], take, seed=3, params=dict(small))
        stem = tmp_path / take
        write_take(res, f"{stem}.abs.gz", f"{stem}.png", f"{stem}.pts", f"{stem}.npz")
        files[take] = {"xyz": f"{stem}.abs.gz", "landmarks": f"{stem}.pts"}
        assert take_file_problems("range", files[take]) == []
        row = _row(take, modality="range")
        with caplog.at_level("WARNING", logger="scan2morph"):
            part = _run_ingest(row, files[take])
        assert "no colour image: shown with its shading" in caplog.text
        data |= part.datasets
        assert data[paths.camera(take, "color_source")] == "shading"
        seen = data[paths.raw(take, "color")][np.isfinite(res["xyz"][..., 2])]
        assert (seen[:, 0] == seen[:, 1]).all() and seen[:, 0].astype(float).std() > 10.0
        assert not part.attrs[paths.take(take)]["grey_color"]  # said once, as geometry-only
    config = repo_config()
    run = Run(Subject("s1", KINDS, {t: t for t in KINDS}), build_template(), config)
    for stage in (repair, landmarks, fit, align):
        data |= stage.apply(data, run)
    params = refine.Params.from_config(config)
    attrs = refine.run(run.template, Take.of(run.subject, "car", data=data), params).attrs
    assert "geometry-only" in attrs[paths.refine_group("car")]["problem"]
    # a sheet row of a range take without its colour column is no problem of the sheet
    sheet = tmp_path / "s.tsv"
    sheet.write_text(
        "subject\ttake\tkind\tlabel\tmodality\txyz\tlandmarks\n"
        f"s1\tneutral\tneutral\tneutral\trange\t{files['neutral']['xyz']}\t"
        f"{files['neutral']['landmarks']}\n"
    )
    assert subject_problems(read_sheet(sheet)) == {"s1": []}
