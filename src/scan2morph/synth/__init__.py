"""Synthetic subjects with exact ground truth.

``head`` builds a procedural head mesh with an opening mouth and iBUG-68 landmarks, ``scanner``
simulates a range scanner (pyrender, headless), and ``cohort`` makes and writes whole takes in
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
    HeadModel,
    Identity,
    articulate,
    build_head,
    label_coefficients,
    sample_identity,
)

__all__ = [
    "DEFAULT_PARAMS",
    "FIELDS",
    "LABEL_COEFFS",
    "LABEL_KIND",
    "HeadModel",
    "Identity",
    "articulate",
    "build_head",
    "default_takes",
    "label_coefficients",
    "make_take",
    "sample_identity",
    "subject_identity",
    "write_take",
]
