"""Every problem of a take's files at once, from cheap reads, before any heavy job.

The take readers (:func:`~scan2morph.io.read_range_take`, ...) stop at the first problem. Here
each file of a take is read on its own by the same reader the ingest uses (so the checks and
their messages are the readers' own, written once), every problem is collected, and when every
file reads, the take's files are checked against each other (image sizes, landmarks inside the
image, the range scan's units and handedness, an RGB-D take's images against its intrinsics and
its frames' data). Nothing heavy runs: no stereo matching, no mesh rendering, no depth
resampling.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.calibration import read_stereo_calibration
from scan2morph.io.depth_image import check_face_depth, depth_frame_paths, read_depth_frames
from scan2morph.io.image import read_color
from scan2morph.io.landmarks import complete, read_pts
from scan2morph.io.mesh_scan import check_mesh_size, read_landmarks3d, read_mesh
from scan2morph.io.mesh_units import check_landmark_units
from scan2morph.io.range_image import read_range
from scan2morph.io.rgbd import check_rgbd_files, read_rgbd_intrinsics
from scan2morph.io.take import (
    check_handedness,
    check_landmarks_inside,
    range_in_mm,
    read_range_take,
    read_stereo_take,
)
from scan2morph.sheet import OPTIONAL_FILES

#: The reader of each file column, per modality (the ingest's own readers).
READERS: dict[str, dict[str, Callable]] = {
    "range": {"xyz": read_range, "color": read_color, "landmarks": read_pts},
    "stereo": {
        "left": partial(read_color, field="left"),
        "right": partial(read_color, field="right"),
        "calibration": read_stereo_calibration,
        "color": read_color,
        "landmarks": read_pts,
    },
    "rgbd": {
        "depth": read_depth_frames,
        "color": read_color,
        "intrinsics": read_rgbd_intrinsics,
        "landmarks": read_pts,
    },
    "mesh": {"mesh": read_mesh, "landmarks": read_landmarks3d},
}


def take_file_problems(
    modality: str, files: Mapping[str, str | Path], mm_per_unit: float = 1.0
) -> list[str]:
    """Every problem of one take's files, one line each (empty: the files are fine).

    Parameters
    ----------
    modality : str
        ``range``, ``stereo``, ``rgbd`` or ``mesh``.
    files : mapping sheet column -> path
        The take's files (a column left out is reported by the sheet check, not here).
    mm_per_unit : float
        The take's unit (the sheet's ``units`` column), mm: a mesh must be face- or head-sized
        in mm once scaled (:func:`~scan2morph.io.mesh_scan.check_mesh_size`), and a range
        scan's face checked in mm once scaled (a wrong unit is named with the column).

    Returns
    -------
    list of str
        The readers' messages (each names the file, the field and what was expected).
    """
    readers = READERS.get(modality, {})
    problems, loaded = [], {}
    for role, reader in readers.items():
        if role not in files:
            continue
        extra = [files.get("texture")] if role == "mesh" else []  # the sheet's optional texture
        try:
            loaded[role] = reader(files[role], *extra)
            if role == "mesh":
                check_mesh_size(loaded[role], mm_per_unit, files[role])
        except InputError as exc:
            problems.append(str(exc))
    required = set(readers) - set(OPTIONAL_FILES.get(modality, ()))
    if problems or required - set(files):
        return problems
    try:
        _cross_check(modality, files, loaded, mm_per_unit)
    except InputError as exc:
        problems.append(str(exc))
    return problems


def _cross_check(
    modality: str, files: Mapping[str, str | Path], loaded: Mapping, mm_per_unit: float
) -> None:
    """The checks between a take's files (sizes, landmarks inside the image, units), on the
    files as their readers ``loaded`` them (a range scan is parsed once, and scaled to mm by
    the sheet's unit as the ingest scales it)."""
    if modality == "range":
        scan = read_range_take(files["xyz"], files.get("color"), files.get("landmarks"), loaded)
        xyz = range_in_mm(scan, mm_per_unit, files["xyz"], files.get("landmarks"))
        if complete(scan.landmarks):  # else checked once detected
            check_handedness(xyz, scan.landmarks, files["xyz"])
    elif modality == "stereo":
        landmarks = files.get("landmarks")
        read_stereo_take(
            files["left"], files["right"], files["calibration"], landmarks, files.get("color")
        )
    elif modality == "mesh":
        if loaded.get("landmarks") is not None:  # their unit against the mesh's (the ingest's)
            extents = np.asarray(loaded["mesh"].extents, dtype=np.float64) * mm_per_unit
            lm3 = np.asarray(loaded["landmarks"], dtype=np.float64) * mm_per_unit
            check_landmark_units(lm3, extents, files["mesh"], files["landmarks"], mm_per_unit)
    elif modality == "rgbd":
        intr, paths = loaded["intrinsics"], depth_frame_paths(files["depth"])
        check_rgbd_files(
            intr, files["intrinsics"], loaded["depth"], paths, loaded["color"], files["color"]
        )
        if loaded.get("landmarks") is not None:
            check_landmarks_inside(loaded["landmarks"], *intr.color.size, files["landmarks"])
        else:  # with landmarks the ingest's face check names a wrong scale
            check_face_depth(loaded["depth"][0], intr.depth_scale_mm, files["intrinsics"])


__all__ = ["READERS", "take_file_problems"]
