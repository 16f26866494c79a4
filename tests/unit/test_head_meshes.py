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
