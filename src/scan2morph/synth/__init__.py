"""Synthetic subjects with exact ground truth.

``head`` builds a procedural head mesh with an opening mouth and iBUG-68 landmarks, ``scanner``
simulates a range scanner (pyrender, headless), ``stereo`` a calibrated stereo rig (two
distorted cameras, a speckle-textured face), and ``cohort`` makes and writes whole takes in
the formats users bring.
"""

from scan2morph.synth.cohort import (
    DEFAULT_PARAMS,
    default_takes,
    make_take,
    subject_identity,
    write_take,
)
from scan2morph.synth.head import (
    FIELDS,
    LABEL_COEFFS,
    LABEL_KIND,
    SEG_SKIN,
    HeadModel,
    Identity,
    articulate,
    build_head,
    label_coefficients,
    sample_identity,
)
from scan2morph.synth.stereo import (
    DEFAULT_RIG,
    make_stereo_take,
    rig_cameras,
    rig_params,
    write_stereo_take,
)

__all__ = [
    "DEFAULT_PARAMS",
    "DEFAULT_RIG",
    "FIELDS",
    "LABEL_COEFFS",
    "LABEL_KIND",
    "SEG_SKIN",
    "HeadModel",
    "Identity",
    "articulate",
    "build_head",
    "default_takes",
    "label_coefficients",
    "make_stereo_take",
    "make_take",
    "rig_cameras",
    "rig_params",
    "sample_identity",
    "subject_identity",
    "write_stereo_take",
    "write_take",
]
