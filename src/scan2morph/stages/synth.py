"""Synth: every take of one synthetic subject, written in the formats users bring (range scans
as FRGC ``.abs.gz`` + PNG, stereo pairs as two PNGs + OpenCV calibration, RGB-D takes as a
16-bit depth PNG + colour PNG + intrinsics YAML, mesh scans as a textured OBJ with 3D
landmarks), with landmark clicks and the exact ground truth (``truth/{take}.npz``)."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence

from scan2morph.synth import make_stereo_take, make_take, write_stereo_take, write_take
from scan2morph.synth.mesh_scan import make_mesh_take, write_mesh_take
from scan2morph.synth.rgbd import make_rgbd_take, write_rgbd_take

#: The files a take of each modality is written to (roles of ``files``, besides the landmarks
#: and the truth), in the writer's order.
ROLES = {
    "range": ("xyz", "color"),
    "stereo": ("left", "right", "calibration"),
    "rgbd": ("depth", "rgbd_color", "intrinsics"),
    "mesh": ("mesh",),
}
#: Each modality's simulator and writer.
_MAKERS = {
    "range": (make_take, write_take),
    "stereo": (make_stereo_take, write_stereo_take),
    "rgbd": (make_rgbd_take, write_rgbd_take),
    "mesh": (make_mesh_take, write_mesh_take),
}
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
    sensors: Mapping[str, Mapping] | None = None,
) -> None:
    """Generate and write the takes of one synthetic subject.

    Parameters
    ----------
    subject : str
        Subject id (with ``seed`` it fixes the identity).
    takes : sequence of mapping
        ``take``, ``kind``, ``label``, ``modality`` (``range``, ``stereo``, ``rgbd`` or
        ``mesh``) of each take.
    seed : int
        The cohort seed (``synthetic.seed``).
    scanner, rig : mapping
        ``synthetic.scanner`` and ``synthetic.stereo.rig``.
    files : mapping role -> sequence of paths
        ``landmarks`` and ``truth`` per take; the roles of :data:`ROLES` per take of that
        modality (in take order).
    sensors : mapping, optional
        ``rgbd`` (``synthetic.rgbd.sensor``) and ``mesh`` (``synthetic.mesh.scanner``).
    """
    params = {"range": scanner, "stereo": rig, **(sensors or {})}
    counts = dict.fromkeys(ROLES, 0)
    for i, t in enumerate(takes):
        args = (subject, t["label"], t["kind"], t["take"])
        modality = t["modality"]
        k = counts[modality]
        counts[modality] += 1
        make, write = _MAKERS[modality]
        result = make(*args, seed=seed, params=dict(params.get(modality, {})))
        own = [files[role][k] for role in ROLES[modality]]
        write(result, *own, files["landmarks"][i], files["truth"][i])
        log.info(
            "%s/%s: %s %s %s written", subject, t["take"], t["modality"], t["kind"], t["label"]
        )
