"""Wavefront OBJ + MTL + PNG texture (opens in MeshLab and Blender with the texture upright).

Vertex order is identical across takes (one template): every vertex is written, so vertex i is
the same template vertex in every take's OBJ. ``v nan nan nan`` would break viewers, so invalid
vertices are written at the position given (callers pass filled positions when they have them;
non-finite rows are written at the centroid of the finite ones, which keeps viewers' zoom-to-fit
on the face) and the faces that touch an invalid vertex are left out, so nothing invalid is drawn.
A comment line ``# invalid: i j ...`` lists the invalid vertices (1-based, as OBJ indices).
Meshes for DCC tools (:mod:`scan2morph.morph.head`) instead place every vertex on a hole-filled
surface and keep every face; a comment line ``# filled: i j ...`` lists the filled vertices.

Texture coordinates are given in the image convention (origin at the image's top-left corner, as
glTF) and written as ``vt u 1-v`` (OBJ's origin is the bottom-left corner), so the texture is
upright in MeshLab and Blender.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scan2morph.errors import InputError, writing
from scan2morph.io.image import write_color

#: The material the models and expressions of a folder share: the neutral's texture, once.
NEUTRAL_MATERIAL = "neutral_texture"


def write_material(folder, name: str, texture) -> str:
    """Write one textured material that several OBJs of ``folder`` share (its name is their
    :func:`write_obj` ``texture``): ``{name}.mtl`` and ``{name}.png``, the texture once instead
    of a copy a mesh.

    Parameters
    ----------
    folder : str or Path
        Where the OBJs are (created).
    name : str
        File stem of the MTL and the PNG.
    texture : (H, W, 3) uint8

    Returns
    -------
    str
        The MTL's file name, for the OBJs' ``mtllib`` lines.
    """
    png = Path(folder) / f"{name}.png"
    png.parent.mkdir(parents=True, exist_ok=True)
    write_color(png, np.asarray(texture, dtype=np.uint8))
    mtl = png.with_suffix(".mtl")
    _write_text(mtl, f"newmtl face\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd {png.name}\n")
    return mtl.name


def write_obj(
    path,
    vertices,
    faces,
    uv=None,
    texture=None,
    valid=None,
    filled=None,
    units: str = "mm",
) -> None:
    """Write a mesh as OBJ, with MTL and PNG texture beside it when ``texture`` is given.

    Parameters
    ----------
    path : str or Path
        ``.obj`` file; ``.mtl`` and ``.png`` take the same stem.
    vertices : (V, 3) float, mm
    faces : (F, 3) int
    uv : (V, 2) float, optional
        Image-convention texture coordinates (top-left origin); written as ``vt u 1-v``.
    texture : (H, W, 3) uint8 or str, optional
        The image, written beside the OBJ; or the file name of a material beside it that
        several meshes share (:func:`write_material`).
    valid : (V,) bool, optional
        Faces touching an invalid (or non-finite) vertex are not written.
    filled : (V,) bool, optional
        Vertices placed by a hole filling rather than measured: their faces are written, and the
        ``# filled:`` comment line lists them (1-based; :func:`read_obj` returns them).
    units : str
        Unit of ``vertices``, named on the header line (``mm``; ``m`` for head-frame meshes).

    Notes
    -----
    Vertex i of the file is vertex i of ``vertices`` in every common reader (trimesh, MeshLab,
    Blender): an invalid vertex keeps its slot, at the mesh's centroid (no data there), is
    listed on the ``# invalid:`` line (1-based, read back by :func:`read_obj`); every vertex no
    written face uses (invalid ones, and valid ones whose faces all touch an invalid vertex) is
    referenced by one degenerate (zero-area) face ``f i i i`` after the real faces, since readers
    such as trimesh drop the vertices no face references (MeshLab drops the degenerate faces
    and keeps the vertices).
    """
    path = Path(path)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise InputError(path, f"vertices: expected (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or (faces.size and not (0 <= faces).all()):
        raise InputError(path, f"faces: expected (F, 3) non-negative indices, got {faces.shape}")
    if faces.size and faces.max() >= len(vertices):
        raise InputError(path, f"faces: index {int(faces.max())} >= {len(vertices)} vertices")
    if uv is not None and np.shape(uv) != (len(vertices), 2):
        raise InputError(path, f"uv: expected ({len(vertices)}, 2), got {np.shape(uv)}")
    finite = np.isfinite(vertices).all(axis=1)
    ok = finite.copy()
    if valid is not None:
        if np.shape(valid) != (len(vertices),):
            raise InputError(path, f"valid: expected ({len(vertices)},), got {np.shape(valid)}")
        ok &= np.asarray(valid, dtype=bool)
    keep = ok[faces].all(axis=1)
    referenced = np.zeros(len(vertices), dtype=bool)
    referenced[faces[keep].ravel()] = True
    lonely = np.flatnonzero(~referenced) + 1  # one degenerate face each keeps them everywhere
    header = f"# scan2morph mesh: {len(vertices)} vertices ({units}), {int(keep.sum())} faces"
    if lonely.size:
        header += f" and {lonely.size} zero-area faces, one on each vertex no face uses"
    lines = [header]
    if filled is not None and np.shape(filled) != (len(vertices),):
        raise InputError(path, f"filled: expected ({len(vertices)},), got {np.shape(filled)}")
    listed = {"invalid": ~ok, "filled": np.zeros(len(vertices), bool) if filled is None else filled}
    if any(np.any(rows) for rows in listed.values()):
        lines.append("# vertex numbers below are OBJ's, from 1: template vertex i is number i + 1")
    for name, rows in listed.items():
        if np.any(rows):
            lines.append(f"# {name}: " + " ".join(str(i) for i in np.flatnonzero(rows) + 1))
    if texture is not None:
        if uv is None:
            raise InputError(path, "texture given without uv")
        if isinstance(texture, str) and not (path.parent / texture).is_file():
            raise InputError(path, f"texture: no material {texture} beside the OBJ")
        if not isinstance(texture, str):
            texture = write_material(path.parent, path.stem, texture)
        lines += [f"mtllib {texture}", "usemtl face"]
    centre = vertices[finite].mean(axis=0) if finite.any() else np.zeros(3)
    v = np.where(finite[:, None], vertices, centre)
    lines += [f"v {a:.6f} {b:.6f} {c:.6f}" for a, b, c in v]
    f1 = faces[keep] + 1
    corner = "{0}/{0}" if uv is not None else "{0}"
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        lines += [f"vt {a:.7f} {1.0 - b:.7f}" for a, b in uv]
    lines += ["f " + " ".join(corner.format(i) for i in tri) for tri in f1]
    if lonely.size:
        lines += [f"f {corner.format(i)} {corner.format(i)} {corner.format(i)}" for i in lonely]
    _write_text(path, "\n".join(lines) + "\n")


def _write_text(path: Path, text: str) -> None:
    """Write a text file; a full disk is one line naming it (OutputError)."""
    with writing(path):
        path.write_text(text)


def write_failed_obj(path, reason: str) -> None:
    """Write the OBJ, MTL and PNG of a take left out of its subject: no vertices, only why.

    Parameters
    ----------
    path : str or Path
        ``.obj`` file; ``.mtl`` and ``.png`` (a blank 1 x 1 texture) take the same stem, so that
        the files a take's mesh is expected in exist and say, when opened, that it has none.
    reason : str
        One line: which stage refused the take and why.
    """
    path = Path(path)
    note = "# scan2morph: no mesh, " + " ".join(str(reason).split())
    write_color(path.with_suffix(".png"), np.full((1, 1, 3), 128, dtype=np.uint8))
    _write_text(path.with_suffix(".mtl"), note + "\n")
    _write_text(path, note + "\n")


def read_obj(path) -> dict[str, np.ndarray]:
    """Read an OBJ written by :func:`write_obj` (a minimal reader: ``v``, ``vt``, triangles).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
        ``vertices`` (V, 3) float64; ``faces`` (F, 3) int64, 0-based; ``uv`` (V, 2) in the image
        convention (v flipped back) or None; ``valid`` (V,) bool from the ``# invalid:`` line;
        ``filled`` (V,) bool from the ``# filled:`` line.

    Raises
    ------
    InputError
        Missing file, a malformed line, or a face that is not a triangle.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found (expected a Wavefront OBJ)")
    verts, tex, faces, invalid, filled = [], [], [], [], []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        parts = line.split()
        try:
            if line.startswith("# invalid:"):
                invalid += [int(i) - 1 for i in parts[2:]]
            elif line.startswith("# filled:"):
                filled += [int(i) - 1 for i in parts[2:]]
            elif parts and parts[0] == "v":
                verts.append([float(t) for t in parts[1:4]])
            elif parts and parts[0] == "vt":
                tex.append([float(t) for t in parts[1:3]])
            elif parts and parts[0] == "f":
                if len(parts) != 4:
                    raise InputError(
                        path, f"line {n}: expected a triangle, got {len(parts) - 1} corners"
                    )
                tri = [int(t.split("/")[0]) - 1 for t in parts[1:]]
                if len(set(tri)) > 1:  # a degenerate face only marks an invalid vertex
                    faces.append(tri)
        except ValueError as exc:
            raise InputError(path, f"line {n}: cannot parse {line[:40]!r} ({exc})") from None
    vertices = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    valid = np.ones(len(vertices), dtype=bool)
    valid[invalid] = False
    is_filled = np.zeros(len(vertices), dtype=bool)
    is_filled[filled] = True
    uv = None
    if tex:
        uv = np.asarray(tex, dtype=np.float64)
        uv[:, 1] = 1.0 - uv[:, 1]
    return {
        "vertices": vertices,
        "faces": np.asarray(faces, dtype=np.int64).reshape(-1, 3),
        "uv": uv,
        "valid": valid,
        "filled": is_filled,
    }
