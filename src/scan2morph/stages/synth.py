"""Synth: every take of one synthetic subject, written in the formats users bring (range scans
as FRGC ``.abs.gz`` + PNG, stereo pairs as two PNGs + OpenCV calibration, RGB-D takes as a
16-bit depth PNG + colour PNG + intrinsics YAML, mesh scans as a textured OBJ with 3D
landmarks), with landmark clicks and the exact ground truth (``truth/{take}.npz``)."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field

from scan2morph.stages.part import Part, Take
from scan2morph.synth import make_stereo_take, make_take, write_stereo_take, write_take
from scan2morph.synth.mesh_scan import make_mesh_take, write_mesh_take
from scan2morph.synth.rgbd import make_rgbd_take, write_rgbd_take
from scan2morph.template import Template

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


@dataclass(frozen=True)
class Params:
    """Synthetic-take parameters.

    Attributes
    ----------
    seed : int
        The cohort seed (``synthetic.seed``; with the subject id it fixes the identity).
    sensors : mapping modality -> mapping
        Each modality's simulated sensor: ``range`` (``synthetic.scanner``), ``stereo``
        (``synthetic.stereo.rig``), ``rgbd`` (``synthetic.rgbd.sensor``) and ``mesh``
        (``synthetic.mesh.scanner``).
    """

    seed: int
    sensors: Mapping[str, Mapping] = field(default_factory=dict)

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's section ``synthetic``."""
        s = config["synthetic"]
        sensors = {
            "range": s["scanner"],
            "stereo": s["stereo"]["rig"],
            "rgbd": s["rgbd"]["sensor"],
            "mesh": s["mesh"]["scanner"],
        }
        return cls(int(s["seed"]), {k: dict(v) for k, v in sensors.items()})


def run(template: Template | None, take: Take, params: Params) -> Part:
    """Generate one take of a synthetic subject.

    Parameters
    ----------
    template : Template or None
        Not used (the contract's shape).
    take : Take
        Its ids (``subject`` with the seed fixes the identity; ``kind``, ``label``) and its
        ``row``'s ``modality`` (``range``, ``stereo``, ``rgbd`` or ``mesh``).
    params : Params

    Returns
    -------
    Part
        No datasets; ``files["modality"]`` and ``files["take"]``, the simulator's result (the
        scan, the clicks and the ground truth) for :func:`write_files`.
    """
    modality = take.row["modality"]
    make, _ = _MAKERS[modality]
    args = (take.subject, take.label, take.kind, take.take)
    result = make(*args, seed=params.seed, params=dict(params.sensors.get(modality, {})))
    return Part(files={"modality": modality, "take": result})


def write_files(part: Part, files: Mapping[str, str]) -> None:
    """Write a synthetic take (:func:`run`) in its modality's formats.

    Parameters
    ----------
    part : Part
        :func:`run`'s.
    files : mapping role -> path
        The roles of :data:`ROLES` of the take's modality, ``landmarks`` and ``truth``.
    """
    modality = part.files["modality"]
    _, write = _MAKERS[modality]
    own = [files[role] for role in ROLES[modality]]
    write(part.files["take"], *own, files["landmarks"], files["truth"])
