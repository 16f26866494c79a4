"""Readers and writers for the formats users bring and the formats we hand out."""

from scan2morph.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "calibration": ("StereoCalibration", "read_stereo_calibration", "write_stereo_calibration"),
        "depth_image": ("read_depth", "write_depth_png"),
        "gltf": ("read_glb_targets", "write_glb"),
        "image": ("read_color", "write_color"),
        "landmarks": ("read_pts", "write_landmarks3d", "write_pts"),
        "mesh_scan": ("MeshTake", "read_landmarks3d", "read_mesh", "read_mesh_take"),
        "obj": ("write_material", "write_obj"),
        "range_image": ("read_abs", "read_npz_range", "read_range", "write_abs", "write_npz_range"),
        "rgbd": (
            "RGBDIntrinsics",
            "RGBDTake",
            "read_rgbd_intrinsics",
            "read_rgbd_take",
            "write_rgbd_intrinsics",
        ),
        "take": (
            "RangeTake",
            "StereoTake",
            "check_face",
            "check_handedness",
            "check_landmarks_inside",
            "read_range_take",
            "read_stereo_take",
        ),
    },
)
