"""Ingest: one take's input files -> its range image, colour and clicked landmarks on one grid.

A range take is read as it is; a stereo take is reconstructed into the range image of its left
camera; an RGB-D take's depth is resampled onto its colour camera's grid
(:mod:`scan2morph.io.rgbd`); a mesh take is rendered through a virtual pinhole camera
(:mod:`scan2morph.io.mesh_scan`). A take's landmark file is optional: its points (``clicks``,
NaN rows for the points a 51-point file leaves out) are written when given; the landmarks stage
completes or detects them. The part records the sheet row, a checksum of every input file
and the camera of the take's pixel grid (``/takes/{take}/camera/*``).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from scan2morph.errors import InputError
from scan2morph.io import (
    StereoCalibration,
    check_face,
    check_handedness,
    read_range_take,
    read_stereo_take,
)
from scan2morph.io.depth_image import depth_frame_paths
from scan2morph.io.landmarks import complete
from scan2morph.io.mesh_scan import SHADED, read_mesh_take
from scan2morph.io.rgbd import read_rgbd_take
from scan2morph.io.take import range_in_mm
from scan2morph.jobs import sha256_file
from scan2morph.scan import reconstruct_stereo
from scan2morph.scan.fusion import FusionParams, fuse_depth_frames
from scan2morph.scan.view import shaded_image
from scan2morph.sheet import FILES, MULTI_PATH_COLUMNS, PATH_SEPARATOR, mm_per_unit
from scan2morph.stages.part import Part, Take
from scan2morph.store import paths

if TYPE_CHECKING:  # a type only: the template (and scipy) stay unimported until used
    from scan2morph.template import Template

#: Config sections this stage reads (stereo takes; mesh takes; RGB-D takes of several frames).
SECTIONS = ("stereo", "mesh_camera", "depth_fusion")
#: What the pixel grid of each modality's take is (``/takes/{take}/camera/model``).
CAMERA_MODELS = {
    "range": "the range scanner's (as given)",
    "stereo": "the stereo rig's left camera (raw, distorted)",
    "rgbd": "the RGB-D sensor's colour camera (intrinsics file)",
    "mesh": "a virtual pinhole camera in front of the face (rendered)",
}
#: ``/takes/{take}/camera/color_source`` of a stereo take whose colour is its texture shot (the
#: sheet's ``color``), not its left image.
TEXTURE_SHOT = "texture shot"
log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """Ingest parameters.

    Attributes
    ----------
    stereo : mapping
        The config section ``stereo`` (the reconstruction of stereo takes).
    mesh_camera : mapping
        The config section ``mesh_camera`` (the virtual camera of mesh takes).
    fusion : FusionParams
        The config section ``depth_fusion`` (RGB-D takes of several depth frames).
    """

    stereo: Mapping = field(default_factory=dict)
    mesh_camera: Mapping = field(default_factory=dict)
    fusion: FusionParams = field(default_factory=FusionParams)

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """From the config's sections ``stereo``, ``mesh_camera`` and ``depth_fusion``."""
        return cls(
            dict(config.get("stereo", {})),
            dict(config.get("mesh_camera", {})),
            FusionParams(**config.get("depth_fusion", {})),
        )


def run(template: Template | None, take: Take, params: Params) -> Part:
    """Read one take.

    Parameters
    ----------
    template : Template or None
        Not used (the contract's shape).
    take : Take
        Its ``row`` (the sheet row: ``subject``, ``take``, ``kind``, ``label``, ``modality``, and
        ``units``: a mesh or range take's coordinates are scaled from it to mm) and ``files``
        (the input files by sheet column, :data:`scan2morph.sheet.FILES` of the modality).
    params : Params

    Returns
    -------
    Part
        ``raw/xyz`` (H, W, 3) mm, ``raw/color`` (H, W, 3) uint8, ``clicks`` (68, 2) px (when
        the take has a landmark file; a mesh take's also ``clicks_3d`` (68, 3) mm, the file's
        points) and ``camera/*`` of the take; the take group's attributes
        hold the row, input checksums, ``nose_depth_mm`` (:func:`~scan2morph.io.check_handedness`,
        with all 68 clicked points) and ``grey_color``.

    Raises
    ------
    InputError
        From the readers; a mirrored (left-handed) frame.
    """
    row, files = take.row, take.files
    name, modality = row["take"], row["modality"]
    if modality not in _READERS:
        raise InputError(f"{row['subject']}/{name}", f"modality {modality!r} not supported")
    scan = _READERS[modality](files, row, params)
    attrs = {k: row[k] for k in ("kind", "label", "modality")} | scan.attrs
    first = FILES[modality][0]
    if complete(scan.landmarks):
        attrs["nose_depth_mm"] = check_handedness(scan.xyz, scan.landmarks, files.get(first, first))
    clicks = {} if scan.landmarks is None else {paths.clicks(name): scan.landmarks}
    if scan.landmarks_3d is not None:
        clicks[paths.clicks_3d(name)] = scan.landmarks_3d
    # a geometry-only mesh is shaded grey on purpose (its own warning says so)
    shaded = scan.camera.get("color_source") == "shading"
    attrs["grey_color"] = bool(_grey(scan.color)) and not shaded
    attrs |= {f"input_sha256_{r}": _checksum(r, path) for r, path in files.items()}
    provenance = {"modality": modality, "model": CAMERA_MODELS[modality]} | scan.camera
    return Part(
        {
            paths.raw(name, "xyz"): scan.xyz,
            paths.raw(name, "color"): scan.color,
            **clicks,
            **{paths.camera(name, k): _dataset(v) for k, v in provenance.items()},
        },
        attrs={paths.take(name): attrs},
    )


class _Scan(NamedTuple):
    """One take on its pixel grid, as a modality's reader gives it."""

    xyz: np.ndarray
    color: np.ndarray
    landmarks: np.ndarray | None
    camera: dict = {}
    attrs: dict = {}
    landmarks_3d: np.ndarray | None = None  # a mesh take's landmark file, mm


def _read_rgbd(files, row, params: Params) -> _Scan:
    fuse = partial(fuse_depth_frames, params=params.fusion)
    scan = read_rgbd_take(
        files["depth"], files["color"], files["intrinsics"], files.get("landmarks"), fuse
    )
    cam = scan.intrinsics.color
    camera = dict(K=cam.K, distortion=cam.D, pose=scan.intrinsics.color_from_depth, size=cam.size)
    attrs = {"depth_frames": 1}
    if scan.fusion is not None:
        f = scan.fusion
        attrs = {
            "depth_frames": len(f.transforms),
            "depth_frame_motion_deg": f.motion_deg,
            "depth_frame_motion_mm": f.motion_mm,
            "depth_frame_rmse_mm": f.rmse_mm,
        }
        log.info(
            "%s/%s: %d depth frames fused (motion up to %.2f degrees, %.2f mm; RMSE %.2f mm)",
            row["subject"], row["take"], len(f.transforms), f.motion_deg.max(),
            f.motion_mm.max(), f.rmse_mm.max(),
        )  # fmt: skip
    return _Scan(scan.xyz, scan.color, scan.landmarks, camera, attrs)


def _read_mesh(files, row, params: Params) -> _Scan:
    scan = read_mesh_take(
        files["mesh"],
        files.get("texture") or None,
        files.get("landmarks"),
        dict(params.mesh_camera),
        mm_per_unit(row),
    )
    camera = dict(
        color_source=scan.report["colour"],
        K=scan.K,
        distortion=np.zeros(5),
        pose=scan.pose,
        size=scan.size,
    )
    return _Scan(
        scan.xyz, scan.color, scan.landmarks, camera, {"mesh": scan.report}, scan.landmarks_3d
    )


def _read_range(files, row, params: Params) -> _Scan:
    scan = read_range_take(files["xyz"], files.get("color"), files.get("landmarks"))
    xyz = range_in_mm(scan, mm_per_unit(row), files["xyz"], files.get("landmarks"))
    if scan.color is not None:
        return _Scan(xyz, scan.color, scan.landmarks)
    log.warning(
        "%s: no colour image: shown with its shading (grey, lit from the scanner); the "
        "texture-driven refinement keeps the template fit",
        row["take"],
    )
    return _Scan(xyz, shaded_image(xyz), scan.landmarks, {"color_source": SHADED})


def _read_stereo(files, row, params: Params) -> _Scan:
    stereo = params.stereo
    pair = read_stereo_take(
        files["left"], files["right"], files["calibration"], files.get("landmarks"),
        files.get("color"),
    )  # fmt: skip
    source = f"{files['left']}, {files['right']}"
    try:
        xyz, report = reconstruct_stereo(
            pair.left, pair.right, pair.calib, dict(stereo), source=source
        )
    except InputError as exc:
        hint = _stereo_hint(pair.left, pair.right, pair.calib, stereo, files)
        if hint:
            raise InputError(exc.source, f"{exc.problem}; {hint}") from None
        raise
    log.info("%s: stereo %s", row["take"], report)
    # the wall-clock timings stay in the log: in the store two identical runs would differ
    report = {k: v for k, v in report.items() if k != "timings_s"}
    # the colour's source is recorded when it is not the left image (the store as before)
    camera = {} if pair.color is None else {"color_source": TEXTURE_SHOT}
    if not complete(pair.landmarks):
        return _Scan(xyz, pair.texture, pair.landmarks, camera, {"stereo": report})
    check_face(
        xyz,
        pair.landmarks,
        files["calibration"],
        files["landmarks"],
        unit_hint=(
            f"; the stereo reconstruction takes its scale from T (baseline |T| = "
            f"{pair.calib.baseline_mm:.4g}): is T in mm?"
        ),
    )
    return _Scan(xyz, pair.texture, pair.landmarks, camera, {"stereo": report})


#: Each modality's reader: (files, row, params) -> _Scan.
_READERS = {"rgbd": _read_rgbd, "mesh": _read_mesh, "range": _read_range, "stereo": _read_stereo}


def _checksum(role: str, path) -> str:
    """SHA-256 of an input file; of every file, joined as in the sheet, for a column that may
    name several (an RGB-D take's depth frames)."""
    if role in MULTI_PATH_COLUMNS:
        return PATH_SEPARATOR.join(sha256_file(p) for p in depth_frame_paths(path))
    return sha256_file(path)


def _grey(color: np.ndarray) -> bool:
    """True for a grey-scale image stored as RGB (every pixel's channels equal)."""
    return bool((color[..., 0] == color[..., 1]).all() and (color[..., 1] == color[..., 2]).all())


def _dataset(value):
    """A camera value as stored: text as it is, numbers as float64 (size as int64) arrays."""
    if isinstance(value, str):
        return value
    arr = np.asarray(value)
    return arr.astype(np.int64 if arr.dtype.kind in "iu" else np.float64)


def _stereo_hint(left, right, calib: StereoCalibration, stereo: Mapping, files) -> str:
    """Why a stereo pair that matched nothing may have failed, tried on the failure path only:
    the images exchanged (with the same calibration), or T in cm or metres instead of mm."""
    tries = [
        (
            right,
            left,
            calib,
            "with left and right exchanged the pair matches: left and right may be swapped",
        ),
    ]
    for factor, unit in ((10.0, "cm"), (1000.0, "metres")):
        scaled = StereoCalibration(
            calib.K1, calib.D1, calib.K2, calib.D2, calib.R, calib.T * factor, calib.image_size
        )
        tries.append(
            (
                left,
                right,
                scaled,
                f"with T x {factor:g} the pair matches: T in "
                f"{files['calibration']} may be in {unit} (baseline |T| = {calib.baseline_mm:.4g}), "
                "expected mm",
            )
        )
    for a, b, c, hint in tries:
        try:
            reconstruct_stereo(a, b, c, dict(stereo), source="retry")
        except InputError:
            continue
        return hint
    return ""
