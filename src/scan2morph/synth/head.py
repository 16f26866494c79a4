"""A procedural human head: a triangle mesh with an opening mouth and 68 iBUG landmarks.

:func:`build_head` meshes a subject's head at rest in a few steps, each in its own module:

- :mod:`~scan2morph.synth.shape`: the head is the zero set of a smooth implicit function
  (ellipsoids blended together, eye sockets and openings carved out);
- :mod:`~scan2morph.synth.skin`: rays from the head centre over a (polar, azimuth) grid that
  is dense over the face mesh its outer surface, cut along the mouth line so that at rest
  the mouth is closed and a deformation opens it;
- :mod:`~scan2morph.synth.features`: a pocket (the oral cavity) closes the surface behind the
  slit and two eyeballs sit in the sockets;
- :mod:`~scan2morph.synth.articulation`: displacement fields and a jaw rotation deform the
  rest mesh (:func:`articulate`); all takes of one subject share one topology;
- :mod:`~scan2morph.synth.albedo`: the colour of every vertex, which also tells the hair and
  the eyebrows apart from the skin;
- :mod:`~scan2morph.synth.landmarks`: the 68 iBUG landmarks as vertex indices.

Head frame (mm): x to the subject's left (image right when facing the camera), y up, z out of
the face; the origin is between the ears at about ear-canal height.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from scan2morph.synth.albedo import _albedo, _hair_segments
from scan2morph.synth.articulation import (
    FIELDS,
    LABEL_COEFFS,
    LABEL_KIND,
    _articulation,
    label_coefficients,
)
from scan2morph.synth.features import (
    SEG_BROW,
    SEG_CAVITY,
    SEG_EYE,
    SEG_HAIR,
    SEG_PUPIL,
    SEG_SKIN,
    SKIN_SEGMENTS,
    _add_features,
)
from scan2morph.synth.ibug import IbugRest, ibug_rest
from scan2morph.synth.identity import Identity, sample_identity
from scan2morph.synth.landmarks import _landmarks
from scan2morph.synth.shape import _Shape
from scan2morph.synth.skin import _mesh_skin

__all__ = [
    "FIELDS",
    "LABEL_COEFFS",
    "LABEL_KIND",
    "SEG_BROW",
    "SEG_CAVITY",
    "SEG_EYE",
    "SEG_HAIR",
    "SEG_PUPIL",
    "SEG_SKIN",
    "SKIN_SEGMENTS",
    "HeadModel",
    "Identity",
    "articulate",
    "build_head",
    "label_coefficients",
    "sample_identity",
]


@dataclass(frozen=True, eq=False)
class HeadModel:
    """A subject's head at rest (the neutral face) with its articulation model.

    Attributes
    ----------
    identity : Identity
    vertices : (N, 3) float64
        Rest positions in the head frame, mm.
    faces : (F, 3) int64
        Triangles, counter-clockwise seen from outside (from the mouth for the cavity).
    segment : (F,) int8
        ``SEG_*`` code of each face.
    albedo : (N, 3) float64
        Base colour of each vertex, RGB in [0, 1].
    landmarks : (68,) int64
        Vertex index of each iBUG-68 landmark.
    fields : dict of str to (N, 3) float64
        Displacement at unit weight of each field in :data:`FIELDS`, mm.
    jaw_weight : (N,) float64
        Fraction of the jaw rotation each vertex follows.
    jaw_pivot : (3,) float64
        A point on the jaw rotation axis (parallel to x), mm.
    slit_upper, slit_lower : (S,) int64
        Vertex indices of the upper and lower copies along the mouth slit (corners excluded).
    mouth : dict
        Mouth geometry at rest, mm: ``corner_x`` (half-width), ``y`` and ``z`` of the centre,
        ``corner_y`` (mean height of the corners).
    rest_mesh : _RestMesh
        The rest mesh the head was built from (its implicit shape; for :attr:`ibug`).
    """

    identity: Identity
    vertices: np.ndarray
    faces: np.ndarray
    segment: np.ndarray
    albedo: np.ndarray
    landmarks: np.ndarray
    fields: dict = field(repr=False)
    jaw_weight: np.ndarray = field(repr=False)
    jaw_pivot: np.ndarray = field(repr=False)
    slit_upper: np.ndarray = field(repr=False)
    slit_lower: np.ndarray = field(repr=False)
    mouth: dict = field(repr=False)
    rest_mesh: object = field(default=None, repr=False)

    @functools.cached_property
    def ibug(self) -> IbugRest:
        """The rest points under the iBUG annotation's conventions (see
        :mod:`~scan2morph.synth.convention`), found on first use: only the ``ibug`` truth
        needs them, not every head built."""
        return ibug_rest(self.rest_mesh, self.segment, self.landmarks)

    @property
    def skin_faces(self) -> np.ndarray:
        """(F,) bool: faces of the outer head surface (not cavity, not eyeball)."""
        return np.isin(self.segment, SKIN_SEGMENTS)


#: Heads kept per process (about 30 MB each): a pipeline job builds one or two; a test worker
#: builds more, and with 8 kept it built two of them twice.
@functools.lru_cache(maxsize=16)
def build_head(identity: Identity) -> HeadModel:
    """Mesh a subject's head at rest and set up its articulation and landmarks.

    Parameters
    ----------
    identity : Identity
        Shape and colour parameters (see :func:`sample_identity`).

    Returns
    -------
    HeadModel
        Cached per identity; its arrays are read-only.
    """
    shape = _Shape(identity)
    mesh = _add_features(shape, _mesh_skin(shape))
    fields, jaw_weight, jaw_pivot = _articulation(mesh)
    albedo, brow_w, hair_w = _albedo(mesh)
    segment = _hair_segments(mesh, brow_w, hair_w)
    arrays = dict(
        vertices=mesh.vertices,
        faces=mesh.faces,
        segment=segment,
        albedo=albedo,
        landmarks=_landmarks(mesh, segment),
        jaw_weight=jaw_weight,
        jaw_pivot=jaw_pivot,
        slit_upper=mesh.slit.upper.astype(np.int64),
        slit_lower=mesh.slit.lower.astype(np.int64),
    )
    for v in list(arrays.values()) + list(fields.values()):
        v.setflags(write=False)
    return HeadModel(
        identity=identity, fields=fields, mouth=mesh.mouth.as_dict(), rest_mesh=mesh, **arrays
    )


def articulate(head: HeadModel, coeffs: dict[str, float]) -> np.ndarray:
    """Vertex positions of a deformed head.

    Parameters
    ----------
    head : HeadModel
    coeffs : dict of str to float
        Weights of the fields in :data:`FIELDS` and ``jaw`` (opening angle in degrees).
        Missing entries are zero; ``{}`` gives the rest (neutral) face exactly.

    Returns
    -------
    vertices : (N, 3) float64
        Head frame, mm.
    """
    v = np.array(head.vertices, dtype=float)
    for k, w in coeffs.items():
        if k == "jaw":
            continue
        v += w * head.fields[k]
    angle = np.deg2rad(coeffs.get("jaw", 0.0)) * head.jaw_weight
    if np.any(angle != 0.0):
        yp, zp = v[:, 1] - head.jaw_pivot[1], v[:, 2] - head.jaw_pivot[2]
        c, s = np.cos(angle), np.sin(angle)
        v[:, 1] = head.jaw_pivot[1] + yp * c - zp * s
        v[:, 2] = head.jaw_pivot[2] + yp * s + zp * c
    return v
