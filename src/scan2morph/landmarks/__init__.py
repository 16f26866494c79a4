"""Zero-click iBUG-68 landmarks from a take's range grid and image.

:func:`detect` finds the face from the geometry and runs a cascaded shape regression trained on
the project's own synthetic heads (:mod:`scan2morph.landmarks.train`); :func:`complete_jawline`
adds the 17 jawline points to a 51-point set; :func:`fit_lips` places a detected mouth on the
lips' colour edge, :func:`fit_brows` its brows on the eyebrows' dark bands, :func:`fit_chin` its
chin on the face's outline below the mouth.
"""

from scan2morph.landmarks.brows import BrowFit, fit_brows
from scan2morph.landmarks.chin import ChinFit, fit_chin
from scan2morph.landmarks.detect import DETECTOR, Detection, detect
from scan2morph.landmarks.jaw import complete_jawline
from scan2morph.landmarks.lips import LipFit, fit_lips

__all__ = [
    "DETECTOR",
    "BrowFit",
    "ChinFit",
    "Detection",
    "LipFit",
    "complete_jawline",
    "detect",
    "fit_brows",
    "fit_chin",
    "fit_lips",
]
