"""Synthetic stereo takes of a face written as a user brings them (the rig of
:func:`scan2morph.synth.make_stereo_take`), for the stereo reader's tests."""

from __future__ import annotations

from pathlib import Path

from scan2morph.synth import make_stereo_take, write_stereo_take

#: A small rig (160 x 120 px, the focal length scaled with it): the reader's checks do not
#: depend on the size.
SMALL_RIG = dict(width=160, height=120, focal_px=325.0)
#: The files of a written take: role -> suffix of the take's stem.
FILE_SUFFIXES = {
    "left": "_left.png",
    "right": "_right.png",
    "calibration": "_calib.yaml",
    "landmarks": ".pts",
    "truth": ".npz",
}


def write_take(result: dict, stem: Path) -> dict[str, Path]:
    """Write a :func:`make_stereo_take` result beside ``stem`` (a path without suffix); its
    files by role (:data:`FILE_SUFFIXES`)."""
    paths = {k: stem.with_name(stem.name + s) for k, s in FILE_SUFFIXES.items()}
    write_stereo_take(result, *paths.values())
    return paths


def neutral(params: dict, **changes) -> dict:
    """Subject s1's neutral (seed 3) seen by the rig ``params`` with ``changes`` to it."""
    return make_stereo_take("s1", "neutral", "neutral", "neutral", seed=3, params=params | changes)
