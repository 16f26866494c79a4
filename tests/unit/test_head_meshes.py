"""Head-frame meshes for DCC tools (scan2morph.morph.head): the hole filling and bad input."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from numpy.testing import assert_allclose

from scan2morph.errors import InputError
from scan2morph.io.obj import read_obj, write_obj
from scan2morph.morph.head import fill_from, write_head_meshes, write_head_obj
from tests.support.meshes import grid_mesh

FRAME = np.diag([1e-3, 1e-3, 1e-3, 1.0])


def test_fill_moves_a_hole_with_its_rim():
    """A take that is the reference shifted by a constant: the filled hole is shifted exactly;
    a linear displacement on the grid is reproduced too (harmonic on a regular grid)."""
    v, f = grid_mesh(12, 10, 5.0, z=lambda x, y: 0.01 * (x - 20) ** 2)
    hole = np.linalg.norm(v[:, :2] - [27.5, 22.5], axis=1) < 11
    for moved in (v + [1.0, -2.0, 3.0], v + np.outer(v[:, 0], [0.0, 0.0, 0.1])):
        filled, missing = fill_from(np.where(hole[:, None], np.nan, moved), f, v)
        assert np.array_equal(missing, hole) and hole.sum() > 10
        assert_allclose(filled, moved, rtol=0, atol=1e-9)


def test_head_obj_lists_filled_vertices_and_keeps_every_face(tmp_path):
    v, f = grid_mesh(6, 5)
    cut = v.copy()
    cut[[8, 9]] = np.nan
    path = tmp_path / "take.obj"
    write_head_obj(path, cut, f, FRAME, reference=v, filled=np.arange(len(v)) == 0)
    mesh = read_obj(path)
    assert np.flatnonzero(mesh["filled"]).tolist() == [0, 8, 9] and mesh["valid"].all()
    assert len(mesh["faces"]) == len(f) and "(m)" in path.read_text().splitlines()[0]
    assert_allclose(mesh["vertices"], v * 1e-3, atol=5e-7)


def test_bad_input_is_refused(tmp_path):
    v, f = grid_mesh(6, 5)
    cut = v.copy()
    cut[3] = np.nan
    with pytest.raises(InputError, match="vertices: NaN rows and no reference mesh"):
        write_head_obj(tmp_path / "a.obj", cut, f, FRAME)
    with pytest.raises(InputError, match=r"filled: expected \(30,\), got \(3,\)"):
        write_obj(tmp_path / "b.obj", v, f, filled=np.ones(3, bool))
    with pytest.raises(InputError, match="store not found"):
        write_head_meshes(tmp_path / "none.h5", tmp_path / "head")
    store = tmp_path / "s.h5"
    with h5py.File(store, "w") as h5:
        h5.attrs["format_version"] = "1.0"
    with pytest.raises(InputError, match="/neutral/head_frame: missing"):
        write_head_meshes(store, tmp_path / "head")


def test_head_obj_opens_in_meshlab_whole(tmp_path):
    """MeshLab's reader (pymeshlab) gets every vertex in its slot and every face: the filled
    vertices are part of the surface, not loose points."""
    import pymeshlab

    v, f = grid_mesh(8, 7, z=lambda x, y: 0.02 * x * y)
    cut = v + [0.0, 0.0, 2.0]
    cut[[17, 18, 25]] = np.nan
    write_head_obj(tmp_path / "h.obj", cut, f, FRAME, reference=v)
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(tmp_path / "h.obj"))
    mesh = ms.current_mesh()
    np.testing.assert_array_equal(mesh.face_matrix(), f)
    assert_allclose(mesh.vertex_matrix(), (v + [0.0, 0.0, 2.0]) * 1e-3, atol=1e-6)


def test_a_takes_head_obj_is_the_correspondence_the_models_are_built_from(tmp_path):
    """The audit's F1: a take's head OBJ held its template fit, before the refinement, while the
    models, the glTF and the store's motion are built from the refined mesh (or the takes'
    consensus): shape keys made from the OBJs were 31-130% off the skin's motion. Each take's
    head OBJ is now its refined mesh (the consensus where one moved it, the aligned fit where no
    refinement ran), textured at the points the refined mesh samples."""
    from scan2morph.store import paths
    from scan2morph.template.sample import texture_uv

    v, f = grid_mesh(8, 7, z=lambda x, y: 0.02 * x * y)
    rng = np.random.default_rng(3)
    color = rng.integers(0, 255, (40, 50, 3), dtype=np.uint8)
    store = tmp_path / "s.h5"
    expect = {}
    with h5py.File(store, "w") as h5:
        h5.attrs["format_version"] = "1.0"
        h5[paths.neutral("head_frame")] = FRAME
        h5[paths.neutral("vertices")] = v
        h5[paths.template("faces")] = f
        for take, groups in (
            ("neutral", ("refine",)),
            ("car", ("refine",)),
            ("too", ("refine", "consensus")),
            ("eel", ()),
        ):
            h5.create_group(paths.take(take)).attrs["kind"] = (
                "neutral" if take == "neutral" else "viseme"
            )
            fit = v + rng.normal(0, 1.0, v.shape)
            valid = np.ones(len(v), dtype=bool)
            h5[paths.align(take, "vertices")] = fit
            h5[paths.mesh(take, "valid")] = valid
            h5[paths.mesh(take, "uv")] = rng.uniform(0, 1, (len(v), 2))
            h5[paths.range_image(take, "color")] = color
            expect[take] = (fit, h5[paths.mesh(take, "uv")][()])
            for group in groups:
                build = paths.refine if group == "refine" else paths.consensus
                moved = v + rng.normal(0, 1.0, v.shape)
                ok = valid.copy()
                ok[[5, 6]] = False
                points = rng.uniform(0, 40, (len(v), 2))
                h5[build(take, "vertices")] = np.where(ok[:, None], moved, np.nan)
                h5[build(take, "valid")] = ok
                h5[build(take, "points2d")] = points
                expect[take] = (np.where(ok[:, None], moved, np.nan), texture_uv(points, 50, 40))
    write_head_meshes(store, tmp_path / "head")
    for take, (vertices, uv) in expect.items():
        mesh = read_obj(tmp_path / "head" / f"{take}.obj")
        measured = np.isfinite(vertices).all(axis=1)
        assert_allclose(mesh["vertices"][measured], vertices[measured] * 1e-3, atol=5e-7)
        assert np.flatnonzero(mesh["filled"]).tolist() == np.flatnonzero(~measured).tolist()
        assert_allclose(mesh["uv"], uv, atol=1e-6)
