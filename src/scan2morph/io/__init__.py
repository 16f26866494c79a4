"""Readers and writers for the formats users bring and the formats we hand out."""

from scan2morph.io.calibration import (
    StereoCalibration,
    read_stereo_calibration,
    write_stereo_calibration,
)
from scan2morph.io.depth_image import read_depth, write_depth_png
from scan2morph.io.gltf import read_glb_targets, write_glb
from scan2morph.io.image import read_color, write_color
from scan2morph.io.landmarks import read_pts, write_pts
from scan2morph.io.mesh_scan import MeshTake, read_landmarks3d, read_mesh, read_mesh_take
from scan2morph.io.obj import write_obj
from scan2morph.io.range_image import (
    read_abs,
    read_npz_range,
    read_range,
    write_abs,
    write_npz_range,
)
from scan2morph.io.rgbd import (
    RGBDIntrinsics,
    RGBDTake,
    read_rgbd_intrinsics,
    read_rgbd_take,
    write_rgbd_intrinsics,
)
from scan2morph.io.take import (
    RangeTake,
    StereoTake,
    check_face,
    check_handedness,
    check_landmarks_inside,
    read_range_take,
    read_stereo_take,
)

__all__ = [
    "MeshTake",
    "RGBDIntrinsics",
    "RGBDTake",
    "RangeTake",
    "StereoCalibration",
    "StereoTake",
    "check_face",
    "check_handedness",
    "check_landmarks_inside",
    "read_abs",
    "read_color",
    "read_depth",
    "read_landmarks3d",
    "read_mesh",
    "read_mesh_take",
    "read_npz_range",
    "read_glb_targets",
    "read_pts",
    "read_range",
    "read_range_take",
    "read_rgbd_intrinsics",
    "read_rgbd_take",
    "read_stereo_calibration",
    "read_stereo_take",
    "write_abs",
    "write_color",
    "write_depth_png",
    "write_glb",
    "write_npz_range",
    "write_obj",
    "write_pts",
    "write_rgbd_intrinsics",
    "write_stereo_calibration",
]
