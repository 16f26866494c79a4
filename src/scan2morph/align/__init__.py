"""Rigid alignment of a subject's takes to its neutral frame (Kabsch initial pose + ICP)."""

from scan2morph.align.icp import (
    AlignMeshes,
    AlignResult,
    IcpParams,
    RmseGate,
    SampledSurface,
    align_take,
    region_motion,
    rmse_gate,
    rmse_limit,
    vertex_normals,
)
from scan2morph.align.noise import MeshNoise, mesh_noise
from scan2morph.align.rigid import (
    invert,
    kabsch,
    rotation_angle_deg,
    transform_points,
    view_turn_deg,
)

__all__ = [
    "AlignMeshes",
    "AlignResult",
    "IcpParams",
    "align_take",
    "invert",
    "kabsch",
    "mesh_noise",
    "MeshNoise",
    "region_motion",
    "SampledSurface",
    "RmseGate",
    "rmse_gate",
    "rmse_limit",
    "rotation_angle_deg",
    "transform_points",
    "vertex_normals",
    "view_turn_deg",
]
