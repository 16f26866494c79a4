"""Synth: every take of one synthetic subject, written in the formats users bring (range scans
as FRGC ``.abs.gz`` + PNG, stereo pairs as two PNGs + OpenCV calibration), with iBUG landmark
clicks and the exact ground truth (``truth/{take}.npz``)."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

from scan2morph.synth import make_stereo_take, make_take, write_stereo_take, write_take

#: Config section this stage reads.
SECTIONS = ("synthetic",)
log = logging.getLogger("scan2morph")


def run(
    subject: str,
    takes: Sequence[Mapping[str, str]],
    seed: int,
    scanner: Mapping,
    rig: Mapping,
    files: Mapping[str, Sequence[str]],
) -> None:
    """Generate and write the takes of one synthetic subject.

    Parameters
    ----------
    subject : str
        Subject id (with ``seed`` it fixes the identity).
    takes : sequence of mapping
        ``take``, ``kind``, ``label``, ``modality`` (``range`` or ``stereo``) of each take.
    seed : int
        The cohort seed (``synthetic.seed``).
    scanner, rig : mapping
        ``synthetic.scanner`` and ``synthetic.stereo.rig``.
    files : mapping role -> sequence of paths
        ``landmarks`` and ``truth`` per take; ``xyz`` and ``color`` per range take; ``left``,
        ``right`` and ``calibration`` per stereo take (in take order).
    """
    counts = {"range": 0, "stereo": 0}
    for i, t in enumerate(takes):
        args = (subject, t["label"], t["kind"], t["take"])
        k = counts[t["modality"]]
        counts[t["modality"]] += 1
        common = (files["landmarks"][i], files["truth"][i])
        if t["modality"] == "stereo":
            result = make_stereo_take(*args, seed=seed, params=dict(rig))
            stereo = (files["left"][k], files["right"][k], files["calibration"][k])
            write_stereo_take(result, *stereo, *common)
        else:
            result = make_take(*args, seed=seed, params=dict(scanner))
            write_take(result, files["xyz"][k], files["color"][k], *common)
        log.info(
            "%s/%s: %s %s %s written", subject, t["take"], t["modality"], t["kind"], t["label"]
        )
