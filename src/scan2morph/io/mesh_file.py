"""A mesh file's own bytes and text, checked before and after trimesh reads it.

trimesh reads what it can and is silent about the rest: a PLY file named ``.obj`` reads as an
OBJ without faces, a face line cut short (a truncated download) is dropped, OBJ index 0 (a
0-based exporter) wraps to the last vertex, and a missing MTL file is replaced by a placeholder
material with a 2 x 2 grey image. These checks find such files from their text and name them.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

from scan2morph.errors import InputError
from scan2morph.io.text_file import BOM

#: The first bytes of the binary mesh formats, by the suffix they take.
MAGIC = {".ply": b"ply", ".glb": b"glTF"}
#: The OBJ statements whose loss matters when a byte-order mark hides a file's first line.
HIDDEN = (b"v", b"vt", b"vn", b"vp", b"f", b"l", b"p", b"mtllib", b"usemtl")
#: How an OBJ vertex line starts (``v``, then a space or a tab).
VERTEX = (b"v ", b"v\t")
#: Format names, for messages.
FORMAT_NAMES = {".obj": "OBJ text", ".ply": "a PLY file", ".glb": "a GLB file", ".gltf": "glTF"}


def check_format(path: Path) -> None:
    """Refuse a mesh file whose first bytes say it is another format than its suffix.

    Raises
    ------
    InputError
        A PLY or GLB file under another suffix (``face.obj`` holding a PLY), binary data named
        ``.obj``, or an OBJ whose first line (not a comment) follows a byte-order mark.
    """
    with path.open("rb") as f:
        head = f.read(4096)
    suffix = path.suffix.lower()
    actual = next((s for s, magic in MAGIC.items() if head.startswith(magic)), None)
    if actual is not None and actual != suffix:
        raise InputError(
            path,
            f"mesh: the file is not {FORMAT_NAMES[suffix]} (it starts with "
            f"{MAGIC[actual].decode()!r}: {FORMAT_NAMES[actual]}); name it {actual}",
        )
    if suffix == ".obj" and b"\x00" in head:
        raise InputError(path, "mesh: the file is not OBJ text (it holds binary data)")
    first = head[len(BOM) :].split(b"\n", 1)[0].strip()
    statement = (first.split() or [b""])[0]
    if suffix == ".obj" and head.startswith(BOM) and statement in HIDDEN:
        # trimesh reads the line as an unknown keyword and drops it: a first vertex lost shifts
        # every face by one vertex (a mesh of wrong triangles when the last vertex is unused);
        # a hidden comment, object or group name costs nothing
        first = first.decode("utf-8", "replace")
        raise InputError(
            path,
            f"mesh: the OBJ starts with a byte-order mark (BOM) before its first line "
            f"{first[:40]!r}, which hides that line from the reader; save it as UTF-8 without BOM",
        )


def load_problem(exc: Exception, path: Path) -> str:
    """The message for an exception trimesh raised reading ``path``."""
    if isinstance(exc, IndexError) and path.suffix.lower() in (".obj", ".ply"):
        # numpy's, from a face list indexing past the vertex list
        return f"faces: a face refers to a vertex the file does not have ({exc})"
    if isinstance(exc, FileNotFoundError) and not Path(str(exc)).is_absolute():
        # trimesh's, with the name a glTF gives one of its buffers or images
        return f"mesh: the file names {str(exc)!r} (a buffer or image), which is missing"
    if "PLY is unexpected length" in str(exc):
        return "mesh: the file is shorter than its PLY header says (cut short?)"
    return f"mesh: cannot read: {str(exc)[:200]}"


def _short_face(refs: int, last: bool) -> str:
    """The message for a face line with ``refs`` < 3 vertices (``last``: the file's last line,
    not ended by a newline)."""
    cut = ": the file looks cut short" if last else ""
    return f"{refs} {'vertex' if refs == 1 else 'vertices'}, expected 3 or more{cut}"


def _relative_problem(path: Path, lines: list[bytes]) -> None:
    """Refuse a negative (relative) face index that counts back past the first vertex."""
    n_vertices = 0
    for number, line in enumerate(lines, start=1):
        head = line.lstrip()[:2]
        if head in (b"v ", b"v\t"):
            n_vertices += 1
        elif head in (b"f ", b"f\t"):
            for ref in line.split()[1:]:
                index = ref.split(b"/", 1)[0]
                if index.startswith(b"-") and index[1:].isdigit() and int(index) + n_vertices < 0:
                    raise InputError(
                        path,
                        f"face line {number}: vertex index {int(index)} counts back past the "
                        f"first vertex ({n_vertices} vertices above it)",
                    )


#: A line's start and its leading whitespace (what ``bytes.lstrip`` strips inside a line): the
#: patterns below are compiled with ``re.M``, so ``^`` is each line's start.
_LEAD = rb"^[ \t\r\x0b\x0c]*"
#: A face line (``f``, then a space or a tab) up to a vertex index 0 (a space or tab, ``0``,
#: then a space, tab, ``/`` or the line's end): the 0-based exporter's face.
_ZERO_INDEX = re.compile(_LEAD + rb"f(?=[ \t])[^\n]*?[ \t]0(?=[ \t/\r\n]|\Z)", re.M)
#: A face line with a minus after a space or a tab (perhaps a relative index).
_FACE_MINUS = re.compile(_LEAD + rb"f(?=[ \t])[^\n]*?[ \t]-", re.M)
#: A vertex line (:data:`VERTEX`) with a comma.
_VERTEX_COMMA = re.compile(_LEAD + rb"v[ \t][^\n]*,", re.M)
#: An OBJ's separators (whitespace and ``/``) as spaces: the text the quick searches look at.
_AS_SPACES = bytes.maketrans(b"\t/\r\n\x0b\x0c", b"      ")
#: A negative integer among the separators (a relative index; also an integer coordinate).
_NEGATIVE_INTEGER = re.compile(rb" -[0-9]+(?= |\Z)")
#: Whitespace at a line's end (what ``bytes.strip`` strips).
_SPACE = b" \t\n\r\x0b\x0c"


def _without_comments(data: bytes) -> bytes:
    """``data`` with each comment (``#`` to the line's end) removed; every line kept."""
    at = data.find(b"#")
    if at < 0:
        return data
    view, kept, start = memoryview(data), [], 0
    while at >= 0:  # views of the text between the comments: one copy, at the join
        kept.append(view[start:at])
        start = data.find(b"\n", at)
        if start < 0:
            break
        at = data.find(b"#", start)
    else:
        kept.append(view[start:])
    return b"".join(kept)


def _line_at(data: bytes, at: int) -> tuple[int, bytes]:
    """The 1-based number and the text (without its newline) of the line of ``data`` holding
    byte ``at``."""
    start = data.rfind(b"\n", 0, at) + 1
    end = data.find(b"\n", at)
    return data.count(b"\n", 0, at) + 1, data[start : len(data) if end < 0 else end]


def check_obj_text(path: Path, data: bytes | None = None) -> None:
    """Refuse an OBJ whose faces trimesh would read wrongly or drop without a word.

    Byte searches over the whole text, no loop over its lines in Python (a 2.3 M vertex,
    360 MB scan in about 1.5 s, where a loop over its lines took 6 s); a file they flag is
    then looked at line by line. An index past the vertices is trimesh's own error
    (:func:`load_problem`).

    Raises
    ------
    InputError
        Naming the line: the file's last line a face with fewer than 3 vertices (a file cut
        short; such a line elsewhere is a stray one trimesh drops), vertex index 0 (0-based
        faces), a negative (relative) index counting back past the first vertex, a vertex line
        with decimal commas. Comments (``#`` to the line's end) are not read. ``data``: the
        file's bytes when the caller has read them (else read here).
    """
    data = _without_comments(path.read_bytes() if data is None else data)
    end = len(data)
    while end and data[end - 1] in _SPACE:  # the last line with text: a cut may end in newlines
        end -= 1
    if end:
        number, last = _line_at(data, end - 1)
        if last.lstrip()[:2] in (b"f ", b"f\t"):  # the file ends inside a face line
            refs = len(last.split()) - 1
            if refs < 3 and not last.rstrip().endswith(b"\\"):  # not a continued line
                raise InputError(path, f"face line {number}: {_short_face(refs, True)}")
    comma = _VERTEX_COMMA.search(data) if b"," in data else None
    if comma is not None:  # trimesh: "string or file could not be read to its end"
        number, line = _line_at(data, comma.start())
        text = line.strip().decode("utf-8", "replace")
        raise InputError(
            path,
            f"vertex line {number}: {text[:60]!r} has decimal commas; expected numbers with "
            "decimal points (an exporter set to a European locale?)",
        )
    spaced = data.translate(_AS_SPACES)  # a zero or negative index is a token of its own
    if b" 0 " in spaced or spaced.endswith(b" 0"):  # a 0 somewhere: is it a face's index?
        if zero := _ZERO_INDEX.search(data):
            raise InputError(
                path,
                f"face line {_line_at(data, zero.start())[0]}: vertex index 0 (OBJ indices "
                "start at 1: were the faces written 0-based?)",
            )
    if _NEGATIVE_INTEGER.search(spaced) and _FACE_MINUS.search(data):  # a relative index?
        _relative_problem(path, data.split(b"\n"))  # each line read


def check_ply_text(path: Path) -> None:
    """Refuse an ASCII PLY cut short: trimesh reads the lines there are and drops the rest
    without a word (a face cut in half read as half a face) or fails on a shape that is not the
    cause (``face colors incorrect shape!``, a point cloud). A binary PLY cut short is trimesh's
    own error (:func:`load_problem`).

    Raises
    ------
    InputError
        Fewer data lines than the header's elements count (naming both), or a last line that
        holds fewer vertex indices than it says (an element of one list property, ``face``).
    """
    with path.open("rb") as f:
        head = f.read(65536)  # the header (a binary PLY's data is not read here)
    end = head.find(b"end_header")
    if end < 0 or head.find(b"format ascii", 0, end) < 0:
        return  # binary, or no header: trimesh's own errors
    data = path.read_bytes()
    elements: list[tuple[str, int, list[str]]] = []
    for line in data[:end].decode("ascii", "replace").splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == "element" and parts[2].isdigit():
            elements.append((parts[1], int(parts[2]), []))
        elif parts[:1] == ["property"] and elements:
            elements[-1][2].append(line)
    body = data[end:].split(b"\n", 1)[1] if b"\n" in data[end:] else b""
    lines = [line for line in body.splitlines() if line.strip()]
    expected = sum(count for _, count, _ in elements)
    counts = " + ".join(f"{count} {name}" for name, count, _ in elements)
    if len(lines) < expected:
        raise InputError(
            path,
            f"mesh: the file is shorter than its PLY header says (cut short?): {len(lines)} data "
            f"lines, expected {expected} ({counts})",
        )
    name, count, properties = elements[-1] if elements else ("", 0, [])
    if count and len(properties) == 1 and properties[0].split()[1:2] == ["list"]:
        values = lines[expected - 1].split()
        if values and values[0].isdigit() and len(values) < 1 + int(values[0]):
            raise InputError(
                path,
                f"mesh: the file's last {name} holds {len(values) - 1} of the {int(values[0])} "
                "vertex indices it says: the file looks cut short",
            )


def uv_problem(path: Path) -> str:
    """Why an OBJ whose material has a texture image reads without texture coordinates.

    trimesh drops every UV of the file when one face line's vertex references mix forms
    (``f 9/9 5/5 1``, as a file cut inside its last reference leaves); without UVs the texture
    cannot be rendered. Read only when that happened (one pass over the face lines).

    Returns
    -------
    str
        The first face line whose references mix forms (its number, two of its forms, and
        that the file looks cut short when it is the last line with text), or that the file
        gives its faces no texture coordinates.
    """
    lines = [line.split(b"#", 1)[0] for line in path.read_bytes().split(b"\n")]  # no comments
    last = max((i for i, line in enumerate(lines) if line.strip()), default=-1)
    for i, line in enumerate(lines):
        if line.lstrip()[:2] not in (b"f ", b"f\t"):
            continue
        refs = [r.decode(errors="replace") for r in line.split()[1:]]
        forms = {(r.count("/"), "//" in r): r for r in refs}
        if len(forms) > 1:
            a, b = list(forms.values())[:2]
            cut = ": the file looks cut short" if i == last else ""
            return (
                f"face line {i + 1}: vertex references of different forms ({a!r} and {b!r}), "
                f"so no face keeps its texture coordinates{cut}; expected one form (v/vt, "
                "v/vt/vn, v//vn or v) throughout a line"
            )
    return (
        "texture: the material has a texture image but the faces have no texture "
        "coordinates (vt); expected UVs for the texture, or a mesh without the texture"
    )


def _mtl_files(path: Path, text: str) -> list[tuple[str, Path | None]]:
    """The ``mtllib`` names of an OBJ's text, each with its file (None: missing)."""
    out = []
    for name in re.findall(r"^\s*mtllib\s+(.+?)\s*$", text, flags=re.M):
        if (path.parent / name).is_file():  # one name, perhaps with spaces
            out.append((name, path.parent / name))
            continue
        for part in name.split():  # several names
            out.append((part, path.parent / part if (path.parent / part).is_file() else None))
    return out


@dataclass(frozen=True)
class ObjMaterials:
    """The materials an OBJ's faces use and what its MTL gives them (:func:`obj_materials`).

    Attributes
    ----------
    mtllib : str or None
        The name on the OBJ's first ``mtllib`` line (the MTL trimesh reads); None without one.
    mtl : Path or None
        That MTL's file, beside the OBJ under the name or its last part; None when missing.
    used : dict of str to int
        Each ``usemtl`` name and the line (1-based) it is first used on.
    defined : frozenset of str
        The MTL's ``newmtl`` names (empty without an MTL).
    with_image : frozenset of str
        Those of them with a texture image (``map_Kd``).
    misread : bool
        The text holds ``mtllib`` before its first ``mtllib`` line (in a comment): trimesh takes
        the name after the first occurrence, so it would look for the wrong file.
    """

    mtllib: str | None
    mtl: Path | None
    used: dict[str, int]
    defined: frozenset[str]
    with_image: frozenset[str]
    misread: bool

    @property
    def colour_only(self) -> bool:
        """Every material the faces use is in the MTL and none has an image: per-material
        colours (``Kd``), which is no texture (trimesh packs two or more of them into an image
        of flat tiles, which would read as one)."""
        named = set(self.used)
        return bool(named) and named <= self.defined and not named & self.with_image


def obj_materials(path: Path, data: bytes | None = None) -> ObjMaterials:
    """Read an OBJ's ``mtllib`` and ``usemtl`` lines and the ``newmtl`` and ``map_Kd`` lines of
    the MTL (comments, ``#`` to the line's end, are not read; byte searches for the keywords,
    not a decoding of the text and a pass over its lines: a few hundredths of a second for a
    360 MB scan). ``data``: the OBJ's bytes when the caller has read them (else read here)."""
    data = path.read_bytes() if data is None else data
    libs = _statements(b"mtllib", data)
    used: dict[str, int] = {}
    for at, name, _ in _statements(b"usemtl", data):
        if name not in used:
            used[name] = data.count(b"\n", 0, at) + 1
    mtllib = libs[0][1] if libs else None
    mtl, defined, with_image = None, set(), set()
    if mtllib is not None:
        places = (path.parent / mtllib, path.parent / Path(mtllib).name)
        mtl = next((p for p in places if p.is_file()), None)
    if mtl is not None:
        current = None
        for line in mtl.read_bytes().decode("utf-8", errors="replace").splitlines():
            words = line.split("#", 1)[0].split()
            if words[:1] == ["newmtl"] and len(words) > 1:
                current = " ".join(words[1:])
                defined.add(current)
            elif words[:1] == ["map_Kd"] and current is not None:
                with_image.add(current)
    first = data.find(b"mtllib")
    misread = first >= 0 and (not libs or libs[0][2] != first)
    return ObjMaterials(mtllib, mtl, used, frozenset(defined), frozenset(with_image), misread)


def _statements(keyword: bytes, data: bytes) -> list[tuple[int, str, int]]:
    """Each ``keyword`` statement line of an OBJ's bytes: where its line starts, its argument
    (comment removed, whitespace joined) and where the keyword starts (byte offsets). Found by
    a byte search for the keyword, each hit then matched from its line's start."""
    statement = re.compile(rb"([ \t]*)" + re.escape(keyword) + rb"[ \t]+([^\n#]*)")
    out, at = [], data.find(keyword)
    while at >= 0:
        start = data.rfind(b"\n", 0, at) + 1
        m = statement.match(data, start)
        if m is not None and m.start() + len(m.group(1)) == at:
            name = " ".join(m.group(2).decode("utf-8", errors="replace").split())
            if name:
                out.append((start, name, at))
        at = data.find(keyword, at + len(keyword))
    return out


def check_obj_materials(path: Path, data: bytes | None = None) -> ObjMaterials:
    """Refuse an OBJ whose faces use a material its MTL does not define.

    trimesh gives such faces its grey stand-in image, and with a second material it packs the
    stand-in into one image with the others: the faces render flat grey and the mesh reads as
    textured. An OBJ whose MTL is missing is left to :func:`stand_in_problem` (the sheet's
    texture column may give the texture). ``data``: the OBJ's bytes when the caller has read
    them.

    Raises
    ------
    InputError
        Naming the material, its line and the MTL's materials.
    """
    found = obj_materials(path, data)
    if found.mtl is None or not found.used:
        return found
    missing = [(n, line) for n, line in found.used.items() if n not in found.defined]
    if missing:
        n, line = missing[0]
        have = ", ".join(repr(d) for d in sorted(found.defined)) or "none"
        raise InputError(
            path,
            f"line {line}: usemtl {n!r} is not in mtllib {found.mtllib!r} (its materials: "
            f"{have}); name a material the MTL defines",
        )
    return found


def stand_in_problem(path: Path, image, materials: ObjMaterials | None = None) -> str | None:
    """Why a mesh's material ``image`` is trimesh's stand-in for a texture it could not read,
    or None when it is not that stand-in.

    trimesh gives faces whose material or image it cannot read a 2 x 2 grey image
    (:data:`PLACEHOLDER_RGBA`): an OBJ whose first ``mtllib`` (the one it reads, beside the OBJ
    or by its own resolver: an absolute path, a subfolder, the bare name) is missing or lacks
    the material the faces use, an OBJ with UVs and no ``mtllib``, a PLY whose texture file is
    missing. Only that stand-in is refused: an MTL trimesh read is the mesh's, whatever its path.
    ``materials``: the OBJ's (:func:`obj_materials`), when already read.
    """
    if not _placeholder(image):
        return None
    if path.suffix.lower() != ".obj":
        return "the mesh has UVs but its texture image could not be read"
    materials = materials or obj_materials(path)
    if materials.mtllib is None:
        return "the mesh has UVs but names no material (no mtllib line)"
    if materials.mtl is not None:
        return f"mtllib {materials.mtllib!r} holds no material the faces use (usemtl)"
    return f"mtllib {materials.mtllib!r} is missing (the mesh has UVs but no material)"


#: The one colour of trimesh's stand-in image for an OBJ material it could not read (RGBA).
PLACEHOLDER_RGBA = (100, 100, 100, 255)


def _placeholder(image) -> bool:
    """Whether ``image`` (PIL or None) is trimesh's 2 x 2 stand-in (:data:`PLACEHOLDER_RGBA`)."""
    if image is None or getattr(image, "size", None) != (2, 2):
        return False
    import numpy as np

    pixels = np.asarray(image.convert("RGBA")).reshape(-1, 4)
    return bool((pixels == PLACEHOLDER_RGBA).all())


def referenced_textures(path: Path) -> list[str]:
    """Texture files an OBJ's MTL files name (``map_Kd``), for the 'texture missing' message."""
    names = []
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return names
    for _, mtl_path in _mtl_files(path, text):
        if mtl_path is not None:
            names += _map_kd(mtl_path)
    return names


def _map_kd(mtl: Path) -> list[str]:
    """The texture names of an MTL file's ``map_Kd`` lines (their options left out)."""
    text = mtl.read_text(encoding="utf-8", errors="replace")
    return re.findall(r"^\s*map_Kd\s+(?:-\S+\s+\S+\s+)*(.+?)\s*$", text, flags=re.M)


def companion_files(path: str | Path, max_bytes: int | None = None) -> list[Path]:
    """The files besides a mesh file that its reader reads, those that exist: an OBJ's MTL files
    (``mtllib``) and their textures (``map_Kd``), a glTF's external buffers and images. A
    change to any of them changes the take (the workflow tracks them with the mesh file).

    Parameters
    ----------
    path : str or Path
        The mesh file (another format, or a file that cannot be read: none).
    max_bytes : int, optional
        Read at most this much of the file (the workflow asks this of every mesh take each
        time it builds its jobs, and a scan can be hundreds of MB): an OBJ's ``mtllib`` lines
        in its first ``max_bytes`` (exporters write them at the top), and a larger glTF's
        none. Default: the whole file.

    Returns
    -------
    list of Path
        In the order the file names them, each once.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".obj", ".gltf"):
        return []
    try:
        if suffix == ".gltf" and max_bytes is not None and path.stat().st_size > max_bytes:
            return []
        with open(path, "rb") as fh:
            data = fh.read(-1 if max_bytes is None else max_bytes)
    except OSError:
        return []
    found = _obj_companions(path, data) if suffix == ".obj" else _gltf_companions(path, data)
    return list(dict.fromkeys(f for f in found if f.is_file()))


def _obj_companions(path: Path, data: bytes) -> list[Path]:
    """An OBJ's MTL files and their textures, found by a scan of its bytes (no decoding)."""
    names, at = [], data.find(b"mtllib")
    while at >= 0:
        start = data.rfind(b"\n", 0, at) + 1
        end = data.find(b"\n", at)
        if not data[start:at].strip():  # the statement begins its line
            line = data[at + 6 : len(data) if end < 0 else end].split(b"#", 1)[0]
            names.append(line.decode("utf-8", errors="replace").strip())
        at = data.find(b"mtllib", at + 6)
    out = []
    for _, mtl in _mtl_files(path, "".join(f"mtllib {n}\n" for n in names if n)):
        if mtl is not None:
            out.append(mtl)
            for name in _map_kd(mtl):
                out += [mtl.parent / name, mtl.parent / Path(name).name]
    return out


def _gltf_companions(path: Path, data: bytes) -> list[Path]:
    """A glTF's external buffers and images (``uri`` not a ``data:`` URI)."""
    try:
        doc = json.loads(data)
    except ValueError:
        return []
    if not isinstance(doc, dict):
        return []
    uris = [
        item.get("uri")
        for key in ("buffers", "images")
        for item in (doc.get(key) or [])
        if isinstance(item, dict)
    ]
    return [
        path.parent / unquote(u) for u in uris if isinstance(u, str) and not u.startswith("data:")
    ]


__all__ = [
    "ObjMaterials",
    "check_format",
    "check_obj_materials",
    "check_obj_text",
    "check_ply_text",
    "companion_files",
    "load_problem",
    "obj_materials",
    "referenced_textures",
    "stand_in_problem",
]
