"""A synthetic subject through the morph stage: a face built on the real template, seen from an
arbitrary right-handed scanner frame, with three visemes and a texture that marks the eyes and the
mouth, and the glTF the stage's writer makes of it (tests of the glTF, its viewers and Blender).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scan2morph.geometry import TexturedMesh
from scan2morph.io.gltf import write_glb
from scan2morph.stages import Subject, morph
from scan2morph.store import paths
from scan2morph.template import build_template, subdivide_template

UNIT_MM = 48.0  # canonical template unit (half the outer-eye distance), mm
TEXTURE = 256
#: Texture colours painted around the landmarks (RGB): subject's right eye, left eye, mouth.
RIGHT_EYE, LEFT_EYE, MOUTH = (0, 200, 0), (220, 0, 0), (0, 0, 220)
SKIN = (200, 170, 150)
VISEMES = {"car": "car", "too": "too", "eel": "eel"}


def _face(template):
    """The template as a face (mm) in a head-like frame (x subject's left, y up, z out)."""
    u, v = template.vertices[:, 0], template.vertices[:, 1]
    z = 25.0 * np.clip(1.0 - (u**2 + (v - 0.9) ** 2) / 0.12, 0, None) ** 2  # the nose
    z -= 12.0 * u**2 + 4.0 * (v - 0.8) ** 2  # a rounded face
    return np.column_stack([UNIT_MM * u, -UNIT_MM * v, z])


def _visemes(template, face):
    u, v = template.vertices[:, 0], template.vertices[:, 1]
    jaw = np.clip((v - 1.5) / 0.8, 0, 1)[:, None]
    lips = np.exp(-(u**2 + (v - 1.72) ** 2) / 0.15)[:, None]
    return {
        "car": face + jaw * [0.0, -9.0, -2.0],
        "too": face + lips * [0.0, 0.0, 6.0] - lips * np.column_stack([2.5 * u, 0 * u, 0 * u]),
        "eel": face + lips * np.column_stack([3.0 * u, 0 * u, 0 * u]) + jaw * [0.0, -2.0, 0.0],
    }


def _texture(template, uv):
    """Skin with coloured discs at the eyes and the mouth (in texture coordinates)."""
    img = np.empty((TEXTURE, TEXTURE, 3), np.uint8)
    img[:] = SKIN
    yy, xx = (np.mgrid[0:TEXTURE, 0:TEXTURE] + 0.5) / TEXTURE
    spots = {
        RIGHT_EYE: ("eye_r_outer", "eye_r_inner"),
        LEFT_EYE: ("eye_l_inner", "eye_l_outer"),
        MOUTH: ("mouth_r", "mouth_l"),
    }
    for colour, names in spots.items():
        c = uv[[template.named[n] for n in names]].mean(axis=0)
        img[(xx - c[0]) ** 2 + (yy - c[1]) ** 2 < 0.035**2] = colour
    return img


def subject_glb(folder: Path):
    """The morph stage's glTF of a face seen from an arbitrary right-handed scanner frame,
    written into ``folder`` as ``viewer.glb``; returns (path, part, subdivided template, data)."""
    template = build_template()
    sub = subdivide_template(template, 1)
    face = _face(sub)
    rng = np.random.default_rng(7)
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot *= np.sign(np.linalg.det(rot))
    shift = np.array([30.0, -80.0, 1000.0])
    to_scanner = lambda p: p @ rot.T + shift  # noqa: E731
    xy = sub.vertices
    uv = (xy - xy.min(axis=0) + 0.05) / (np.ptp(xy, axis=0) + 0.1)
    data = {
        paths.neutral("vertices"): to_scanner(face),
        paths.mesh("neutral", "uv"): uv,
        paths.range_image("neutral", "color"): _texture(sub, uv),
    }
    data |= {paths.viseme(t, "model"): to_scanner(m) for t, m in _visemes(sub, face).items()}
    subject = Subject(
        "viewer",
        {"neutral": "neutral"} | dict.fromkeys(VISEMES, "viseme"),
        {"neutral": "neutral"} | VISEMES,
    )
    config = {
        "morph": {"blends": {}, "pca_blends": {}, "alpha_limit": 3.0, "sigma": "sample"},
        "template": {"subdivision_levels": 1},
    }
    part = morph.run(template, subject, data, morph.Params.from_config(config))
    f = part.files
    path = Path(folder) / "viewer.glb"
    # as stages.morph.write_files writes it
    write_glb(
        path, TexturedMesh(f["shapes"]["neutral"], f["faces"], f["uv"], f["texture"]), f["targets"]
    )
    return path, part, sub, data
