"""Bad input as a new user brings it (issue: bad-input sweep): each case one line naming the
file, the field and what was expected, where before it gave a traceback, a cryptic line or
silent garbage. Small files written here, read by the library's readers and the sheet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scan2morph.errors import InputError
from scan2morph.io import read_mesh

TETRA_V = np.array([[0.0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _one_line(exc: pytest.ExceptionInfo, source) -> str:
    text = str(exc.value)
    assert "\n" not in text and text.startswith(str(source))
    return text


def _obj(path: Path, vertices, faces) -> Path:
    lines = [f"v {x} {y} {z}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_good_tetrahedron_reads(tmp_path):
    mesh = read_mesh(_obj(tmp_path / "t.obj", TETRA_V, TETRA_F))
    assert len(mesh.faces) == 4


def test_a_mesh_with_a_nan_vertex_is_one_line_not_a_kdtree_traceback(tmp_path):
    vertices = TETRA_V.copy()
    vertices[2, 1] = np.nan
    path = _obj(tmp_path / "nan.obj", vertices, TETRA_F)
    with pytest.raises(InputError) as exc:
        read_mesh(path)
    assert _one_line(exc, path) == (
        f"{path}: vertices: 1 of 4 have a NaN or infinite coordinate (the first: vertex 3); "
        "expected finite numbers"
    )


def test_a_face_indexing_past_the_vertices_is_named(tmp_path):
    faces = TETRA_F.copy()
    faces[1, 2] = 9
    path = _obj(tmp_path / "past.obj", TETRA_V, faces)
    with pytest.raises(InputError, match="faces: a face refers to a vertex the file does not have"):
        read_mesh(path)


@pytest.mark.parametrize("name", ["z.glb", "z.ply", "z.obj"])
def test_an_empty_mesh_file_says_so(tmp_path, name):
    (tmp_path / name).write_bytes(b"")
    with pytest.raises(InputError) as exc:
        read_mesh(tmp_path / name)
    assert _one_line(exc, tmp_path / name).endswith(
        "mesh: the file is empty (0 bytes; expected an OBJ, PLY or glTF/GLB)"
    )
