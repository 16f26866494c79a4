"""The RMSE gate of an alignment: the point-to-plane RMSE a right alignment leaves, from the
meshes' measured noise (:func:`rmse_limit`), and the verdict on a given pose (:func:`rmse_gate`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scan2morph.align.noise import mesh_noise, tail_rms
from scan2morph.align.rigid import transform_points
from scan2morph.align.settings import (
    AlignMeshes,
    IcpParams,
    check_indices,
    check_mesh,
    icp_settings,
    noise_gains,
)
from scan2morph.align.surface import SampledSurface
from scan2morph.align.trim import trim_moving
from scan2morph.errors import InputError
from scan2morph.geometry import vertex_normals

#: The relative RMSE limit is never below this, mm: on noise-free meshes the expected RMSE is
#: zero, but the template's vertices of two takes sample the skin at different points and the
#: point-to-plane residual of curved skin is not (0.02-0.05 mm on the synthetic faces).
_RMSE_FLOOR_MM = 0.1


@dataclass(frozen=True)
class RmseGate:
    """The RMSE gate of an alignment (:func:`rmse_gate`).

    Attributes
    ----------
    residual_rmse : float
        RMS point-to-plane distance of the region's take vertices to the neutral mesh, mm.
    noise_take, noise_neutral : float
        Measured noise of the take's and the neutral's region, mm.
    limit : float
        The limit used, mm (:func:`rmse_limit`).
    kind : str
        ``"relative"`` or ``"absolute"``.
    problem : str or None
        Why the gate failed (naming the RMSE, the measured noise and the limit); None if passed.
    kept : float
        Share of the region judged (the rest left out as moved, as :func:`align_take` trims).
    """

    residual_rmse: float
    noise_take: float
    noise_neutral: float
    limit: float
    kind: str
    problem: str | None
    kept: float = 1.0


def rmse_gate(
    meshes: AlignMeshes,
    icp_indices: np.ndarray,
    transform: np.ndarray,
    params: IcpParams | None = None,
    source: str = "subject/take",
) -> RmseGate:
    """Judge a given take -> neutral pose by the RMSE gate :func:`align_take` applies.

    The region's parts that moved are left out as :func:`align_take` trims them (at the given
    pose, which is not refined), and the RMSE of the rest is compared with :func:`rmse_limit`.

    Parameters
    ----------
    meshes, icp_indices
        As :func:`~scan2morph.align.align_take`.
    transform : (4, 4) float
        Take scanner frame -> neutral frame.
    params : IcpParams, optional
        Its ``max_rmse_ratio``, ``max_rmse_mm`` and ``trim_*`` are used.
    source : str
        ``subject/take`` for messages.

    Returns
    -------
    RmseGate
    """
    prm = icp_settings(params, source)
    src, sv = check_mesh(meshes.src_vertices, meshes.src_valid, "src", source)
    dst, dv = check_mesh(meshes.dst_vertices, meshes.dst_valid, "dst", source, src.shape[0])
    region = np.zeros(src.shape[0], dtype=bool)
    region[check_indices(icp_indices, src.shape[0], "icp_indices", source)] = True
    normals = vertex_normals(dst, np.asarray(meshes.faces))
    target = region & dv & np.isfinite(normals).all(axis=1)
    p_idx = np.flatnonzero(region & sv)
    if p_idx.size < 3 or np.count_nonzero(target) < 3:
        raise InputError(source, "icp_indices: fewer than 3 valid region vertices")
    q_idx = np.flatnonzero(target)
    gains = noise_gains(meshes, source)
    noise_take = mesh_noise(src, sv, at=p_idx, source=source).region(p_idx) * gains[0]
    noise_neutral = mesh_noise(dst, dv, at=q_idx, source=source).region(q_idx) * gains[1]
    plane = SampledSurface(dst[target], normals[target], source).plane
    p = src[p_idx]
    t = np.asarray(transform, dtype=np.float64)

    def fixed(keep, pose):  # the pose is judged, not refined
        return pose, 0.0, 0.0, 0, True

    keep, *_ = trim_moving(p, np.ones(len(p), dtype=bool), t, True, fixed, plane, prm)
    gate = residual_gate(plane(transform_points(t, p[keep])), noise_take, noise_neutral, prm)
    return replace(gate, kept=float(keep.mean()))


def residual_gate(residuals, noise_take, noise_neutral, prm, robust: bool = False) -> RmseGate:
    """The RMSE gate of point-to-plane ``residuals`` (n,) mm, given the measured noise of the
    two sides (mm) and the ICP settings ``prm`` (``max_rmse_ratio``, ``max_rmse_mm``); with
    ``robust`` the RMS is :func:`~scan2morph.align.noise.tail_rms`'s."""
    if not residuals.size:
        rmse = float("inf")
    elif robust:
        rmse = tail_rms(residuals)
    else:
        rmse = float(np.sqrt(np.mean(residuals**2)))
    limit, kind = rmse_limit(noise_take, noise_neutral, prm)
    problem = _rmse_verdict(rmse, limit, kind, noise_take, noise_neutral, prm, robust)
    return RmseGate(rmse, float(noise_take), float(noise_neutral), limit, kind, problem)


def rmse_limit(noise_take: float, noise_neutral: float, params: IcpParams) -> tuple:
    """The point-to-plane RMSE above which an alignment is poor.

    Parameters
    ----------
    noise_take, noise_neutral : float
        Measured noise (standard deviation) of the take's and the neutral's ICP region, mm;
        NaN when unknown (counted as 0).
    params : IcpParams
        Its ``max_rmse_ratio`` and ``max_rmse_mm`` (None: relative).

    Returns
    -------
    limit : float
        mm: ``max_rmse_mm`` if set, else ``max_rmse_ratio * sqrt(noise_take^2 +
        noise_neutral^2)``, at least :data:`_RMSE_FLOOR_MM`.
    kind : str
        ``"absolute"`` or ``"relative"``.
    """
    if params.max_rmse_mm is not None:
        return float(params.max_rmse_mm), "absolute"
    expected = np.hypot(*(x if np.isfinite(x) else 0.0 for x in (noise_take, noise_neutral)))
    return float(max(params.max_rmse_ratio * expected, _RMSE_FLOOR_MM)), "relative"


def _rmse_verdict(
    residual_rmse, limit, kind, noise_take, noise_neutral, prm, robust=False
) -> str | None:
    """The RMSE gate's problem, naming the measured noise and the limit; None when it passed."""
    if residual_rmse <= limit:
        return None
    noise = f"measured noise: take {noise_take:.3f} mm, neutral {noise_neutral:.3f} mm"
    if kind == "absolute":
        why = f"max_rmse_mm {limit:g} (absolute; {noise})"
    else:
        expected = np.hypot(noise_take, noise_neutral)
        why = (
            f"limit {limit:.3f} mm (max_rmse_ratio {prm.max_rmse_ratio:g} x the "
            f"{expected:.3f} mm a right alignment leaves; {noise})"
        )
    what = "robust point-to-plane RMS" if robust else "point-to-plane RMSE"
    return (
        f"{what} {residual_rmse:.3f} mm over the kept region > {why}: "
        "misaligned, or the stable region moved"
    )


__all__ = ["RmseGate", "rmse_gate", "rmse_limit"]
