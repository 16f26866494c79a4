"""The parameters of one synthetic subject: head shape factors and colour tones."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Identity:
    """The shape and colour parameters of one synthetic subject.

    Scale factors are relative to an average adult head (1.0); tones are in [0, 1].

    Attributes
    ----------
    width, height, depth : float
        Scale of the whole head along x, y and z.
    nose, nose_width : float
        Nose length (and projection), nose width.
    lips, mouth_width : float
        Lip thickness, mouth width.
    eye_spacing : float
        Distance between the eyes.
    brow_mm : float
        Brow height above the average, mm.
    chin : float
        Chin width.
    skin_tone, hair_tone : float
        Position along the skin and hair colour ramps, light to dark and dark to light.
    iris : int
        Iris colour: 0 brown, 1 blue, 2 green.
    eyes_closed : bool
        Lids closed over the eyeballs (no eyeball shows; the lid points of the truth lie on
        the lid line, as iBUG annotates closed eyes).
    eye_height_mm : float
        Height of the eyes (and the sockets, openings and brows with them) above the
        average, mm; the nose and the rest of the face stay.
    face_width : float
        Width of the face below the eyes (mid-face, cheeks, jaw), on top of ``width``.
    brow_hair : float
        Opacity of the eyebrow hair in [0, 1] (0.9 average; 0 none).
    hairline_mm : float
        Height of the scalp's hairline above the average, mm (large: bald).

    The last five are 0 / 1 / 0.9 at their defaults, which give the same head as an
    identity without them; :func:`sample_identity` never varies them (the detector's
    trainer does, :mod:`scan2morph.landmarks.data`).
    """

    width: float = 1.0
    height: float = 1.0
    depth: float = 1.0
    nose: float = 1.0
    nose_width: float = 1.0
    lips: float = 1.0
    mouth_width: float = 1.0
    eye_spacing: float = 1.0
    brow_mm: float = 0.0
    chin: float = 1.0
    skin_tone: float = 0.3
    hair_tone: float = 0.2
    iris: int = 0
    eyes_closed: bool = False
    eye_height_mm: float = 0.0
    face_width: float = 1.0
    brow_hair: float = 0.9
    hairline_mm: float = 0.0


def sample_identity(rng: np.random.Generator) -> Identity:
    """Draw a plausible identity.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness (seed it for reproducible subjects).

    Returns
    -------
    Identity
    """
    n = np.clip(rng.standard_normal(10), -2.5, 2.5)
    return Identity(
        width=float(1 + 0.04 * n[0]),
        height=float(1 + 0.04 * n[1]),
        depth=float(1 + 0.04 * n[2]),
        nose=float(1 + 0.08 * n[3]),
        nose_width=float(1 + 0.08 * n[4]),
        lips=float(1 + 0.12 * n[5]),
        mouth_width=float(1 + 0.06 * n[6]),
        eye_spacing=float(1 + 0.03 * n[7]),
        brow_mm=float(2.0 * n[8]),
        chin=float(1 + 0.1 * n[9]),
        skin_tone=float(rng.uniform(0.0, 1.0)),
        hair_tone=float(rng.uniform(0.0, 1.0)),
        iris=int(rng.integers(0, 3)),
    )
