"""The OBJ text checks (scan2morph.io.mesh_file.check_obj_text, obj_materials) as byte searches
over the whole file: the lines they name and the files they pass, edge by edge (comments,
tabs, a 0 before a comment, a minus after a vertical tab, a continued last line), and the
materials read without decoding the text."""

from __future__ import annotations

import pytest

from scan2morph.errors import InputError
from scan2morph.io.mesh_file import check_obj_text, obj_materials

VERTICES = b"v 0.0 0.0 0.0\nv 1.0 0.0 0.0\nv 0.0 1.0 0.0\nvt 0 0\n"


def _obj(tmp_path, body: bytes):
    path = tmp_path / "scan.obj"
    path.write_bytes(body)
    return path


@pytest.mark.parametrize(
    "body",
    [
        VERTICES + b"f 1 2 3\n",
        VERTICES + b"f 1 2 3",  # no newline at the end
        VERTICES + b"f 1 2 3 # 0 -9 \n",  # a 0 and a minus in a comment
        VERTICES + b"# f 0 1 2\nf 1 2 3\n",  # a commented-out face
        VERTICES + b"f 1/0 2/0 3/0\n",  # texture index 0: not the vertex's
        VERTICES + b"f 1 2 03\n",
        VERTICES + b"f -3 -2 -1\n",  # relative, within the vertices
        VERTICES + b"f 1 2\nf 1 2 3\n",  # a stray short face before the last line
        VERTICES + b"f 1 2 \\\n",  # a continued last line
        VERTICES + b"vn 0,1 0 1\nf 1 2 3\n",  # a comma on a normal's line, not a vertex's
        VERTICES + b"f\x0b0 1 2\n",  # a vertical tab is not a separator the check reads
        b"f 1 2 3\x0b-9\n" + VERTICES,  # a minus after a vertical tab: not an index counted back
        b"",
        # a word ending in f or v mid-line is no statement (the review: the patterns were not
        # tied to a line's start, and these valid files were refused)
        VERTICES + b"g Half 0\nf 1 2 3\n",
        VERTICES + b"usemtl leaf 0\nf 1 2 3\n",
        b"o Scan rev 2, cleaned\n" + VERTICES + b"f 1 2 3\n",
        b"v inf 0 0\n" + VERTICES + b"f 1 2 3\n",
    ],
)
def test_passes(tmp_path, body):
    check_obj_text(_obj(tmp_path, body))


@pytest.mark.parametrize(
    ("body", "match"),
    [
        (VERTICES + b"f 0 1 2\n", r"face line 5: vertex index 0"),
        (VERTICES + b"f\t1\t0\t2\n", r"face line 5: vertex index 0"),
        (VERTICES + b"f 1 2 0#c\nf 1 2 3\n", r"face line 5: vertex index 0"),
        (VERTICES + b"f 1 2 3\n  f 1 0/1 2\n", r"face line 6: vertex index 0"),
        (VERTICES + b"f 1 2 3\nf 1 2 0", r"face line 6: vertex index 0"),
        (VERTICES + b"f 1 2 0\r\n", r"face line 5: vertex index 0"),
        (VERTICES + b"f 1 2\n\n  \n", r"face line 5: 2 vertices, expected 3 or more: the file"),
        (VERTICES + b"f 1 # 2 3\n# the end\n", r"face line 5: 1 vertex, expected 3"),
        (b"v 1,5 2 3\n" + VERTICES + b"f 1 2 3\n", r"vertex line 1: 'v 1,5 2 3' has decimal"),
        (VERTICES + b"\tv 1 2,0 3 # x\nf 1 2 3\n", r"vertex line 5: 'v 1 2,0 3' has decimal"),
        (VERTICES + b"f -1 -2 -3\nf 1 2 -9\n", r"face line 6: vertex index -9 counts back"),
        (b"f -1/-1 2 3\n" + VERTICES, r"face line 1: vertex index -1 counts back past the first"),
    ],
)
def test_refuses_naming_the_line(tmp_path, body, match):
    with pytest.raises(InputError, match=match):
        check_obj_text(_obj(tmp_path, body))


def test_materials_found_by_their_lines(tmp_path):
    (tmp_path / "skin.mtl").write_text("newmtl skin\nmap_Kd skin.png\nnewmtl eye # left\n")
    body = (
        b"# exported by mtllib-tool\n"  # the word in a comment first: trimesh misreads it
        b"mtllib  skin.mtl  # the skin\n" + VERTICES + b"usemtl skin\nf 1 2 3\n"
        b"  usemtl\teye  # comment\nf 1 2 3\nusemtlx no\n# usemtl commented\nusemtl skin\n"
        b"usemtl caf\xc3\xa9 au lait\n"
    )
    found = obj_materials(_obj(tmp_path, body))
    assert found.mtllib == "skin.mtl" and found.mtl == tmp_path / "skin.mtl"
    assert found.used == {"skin": 7, "eye": 9, "café au lait": 14}
    assert found.defined == {"skin", "eye"} and found.with_image == {"skin"}
    assert found.misread
    plain = obj_materials(_obj(tmp_path, b"mtllib skin.mtl\n" + VERTICES))
    assert not plain.misread and plain.used == {}
