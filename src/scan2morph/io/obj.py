"""Wavefront OBJ + MTL + PNG texture (opens in MeshLab and Blender with the texture upright).

Vertex order is identical across takes (one template): every vertex is written, invalid ones as
``v nan nan nan`` would break viewers, so invalid vertices are written at the position given
(callers pass filled positions when they have them, NaN rows become 0 0 0) and the faces that
touch an invalid vertex are left out, so nothing invalid is ever drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.image import write_color


def write_obj(path, vertices, faces, uv=None, texture=None, valid=None) -> None:
    """Write a mesh as OBJ, with MTL and PNG texture beside it when ``texture`` is given.

    Parameters
    ----------
    path : str or Path
        ``.obj`` file; ``.mtl`` and ``.png`` take the same stem.
    vertices : (V, 3) float, mm
    faces : (F, 3) int
    uv : (V, 2) float, optional
        Image-convention texture coordinates (top-left origin); written as ``vt u 1-v``.
    texture : (H, W, 3) uint8, optional
    valid : (V,) bool, optional
        Faces touching an invalid (or non-finite) vertex are not written.
    """
    path = Path(path)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise InputError(path, f"vertices: expected (V, 3), got {vertices.shape}")
    ok = np.isfinite(vertices).all(axis=1)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)
    keep = ok[faces].all(axis=1)
    lines = [f"# scan2morph mesh: {len(vertices)} vertices (mm), {int(keep.sum())} faces"]
    if texture is not None:
        if uv is None:
            raise InputError(path, "texture given without uv")
        write_color(path.with_suffix(".png"), np.asarray(texture, dtype=np.uint8))
        path.with_suffix(".mtl").write_text(
            f"newmtl face\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd {path.with_suffix('.png').name}\n"
        )
        lines += [f"mtllib {path.with_suffix('.mtl').name}", "usemtl face"]
    v = np.where(np.isfinite(vertices), vertices, 0.0)
    lines += [f"v {a:.6f} {b:.6f} {c:.6f}" for a, b, c in v]
    f1 = faces[keep] + 1
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        lines += [f"vt {a:.7f} {1.0 - b:.7f}" for a, b in uv]
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in f1]
    else:
        lines += [f"f {a} {b} {c}" for a, b, c in f1]
    path.write_text("\n".join(lines) + "\n")
