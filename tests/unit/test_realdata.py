"""Checks on real geometry: nothing in the pipeline may be tuned to the synthetic generator.

Data: "Infinite, 3D Head Scan" by Lee Perry-Smith / Infinite-Realities, based on a work at
www.triplegangers.com, licensed CC BY 3.0 (https://creativecommons.org/licenses/by/3.0/). It
is read from ``../shared/data/lee-perry-smith`` (next to the repository clone, also in CI) and
never copied into the repository; every test here skips when it is absent.

The scene
---------
* **Units.** The mesh's units are arbitrary (face toward +z, +y up). We scale it so that the
  head is 150 mm wide at the ears, a typical adult head breadth: the widest x extent of the
  vertices above the neck (model y > 0.6; jaw and neck below are under 2.6 units wide, the
  ears 3.62) becomes 150 mm, i.e. 41.4 mm per unit. Chin to crown is then 185 mm and the
  outer eye corners lie about 85 mm apart (read off a frontal rendering), a little under the
  data README's 90 mm cue; nothing below depends on the scale to within 10 %.
* **Frames.** Model frame: the scaled mesh. The whole scene (mesh, camera, rig) is then moved
  into a *scanner frame* by a seeded random rotation and translation, so that no axis
  convention can be assumed by the code under test; all ray casting happens in that frame.
* **Range scan.** A pinhole camera, 640 x 480, about 760 mm in front of the nose tip (800 mm
  from a target 40 mm behind it), turned 10 degrees in yaw and 5 in pitch, its focal length
  chosen so that the head (chin to crown) fills 60 % of the image height. Rays go through
  the pixel centres ((0, 0) = centre of the top-left pixel) and are cast with
  :class:`open3d.t.geometry.RaycastingScene` (float32); the hit is then recomputed in float64
  as the intersection of the ray with the plane of the hit triangle, so the truth is exact up
  to float64 rounding.
* **Stereo.** Two cameras 120 mm apart, each turned 3 degrees inwards, mild radial distortion
  (k1 = -0.05), rays through the distorted pixels (2 x 2 supersampling). The surface shows the
  scan's colour map (V flipped) blended with a random speckle pattern projected from the rig
  centre (view independent, as the stereo method requires a random texture), Lambert shading
  from the rig centre, 1 grey level of sensor noise.
* **Modal.** The face in front of the ears, cut from the mesh with its UV seams welded.

Run with ``pytest -s`` to see the measured figures.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import trimesh
from scipy import ndimage
from scipy.spatial.transform import Rotation

from scan2morph.errors import InputError
from scan2morph.io.calibration import StereoCalibration
from scan2morph.modal import ModalParams, modal_basis, project, reconstruct
from scan2morph.modal.fem import DOF, check_mesh
from scan2morph.open3d_light import open3d
from scan2morph.scan import DEFAULT_REPAIR, reconstruct_stereo, repair_range
from tests.support.configs import repo_config
from tests.support.real_head import COLOR_MAP, DATA_DIR, GLB, smile_displacement
from tests.support.stereo_scene import pixel_rays

o3d = open3d()  # open3d without its web viewer, as the library imports it

_MISSING = [p.name for p in (GLB, COLOR_MAP) if not p.is_file()]

pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(
        bool(_MISSING),
        reason=f"real head scan absent: {DATA_DIR} lacks {', '.join(_MISSING)} "
        "(Lee Perry-Smith head, CC BY 3.0; see ../shared/data/README.md)",
    ),
]

SEED = 20240611
HEAD_WIDTH_MM = 150.0  # head breadth at the ears after scaling
NECK_TOP_UNITS = 0.6  # model y (file units) above which the vertices belong to the head
WIDTH, HEIGHT = 640, 480
DISTANCE_MM = 800.0  # camera (rig centre) to the aiming point 40 mm behind the nose tip
FACE_FILL = 0.6  # fraction of the image height the head (chin to crown) fills
FRONT_MM = 40.0  # "face": at least this far in front of the ears (model z)
NOISE_MM = 0.1  # range noise along the ray, 1 sigma
BASELINE_MM = 120.0
TOE_IN_DEG = 3.0


# --------------------------------------------------------------------------------------------
# the real head


@dataclass
class Head:
    """The scan in mm, in its model frame and in the random scanner frame."""

    vertices: np.ndarray  # (V, 3) model frame, mm
    faces: np.ndarray  # (F, 3) int64 (UV seams split vertices)
    uv: np.ndarray  # (V, 2), V flipped (OBJ convention: v = 0 at the image bottom)
    normals: np.ndarray  # (V, 3) unit, model frame
    texture: np.ndarray  # (1024, 1024, 3) uint8 RGB
    mm_per_unit: float
    nose: np.ndarray  # (3,) nose tip, model frame, mm
    ear_z: float  # model z of the ear extremes, mm
    chin_y: float
    crown_y: float
    R_w: np.ndarray  # model -> scanner rotation
    t_w: np.ndarray  # model -> scanner translation, mm
    scene: o3d.t.geometry.RaycastingScene  # the mesh in the scanner frame (float32)
    vertices_w: np.ndarray  # (V, 3) scanner frame, mm (float64)

    def to_model(self, p_w: np.ndarray) -> np.ndarray:
        """Scanner-frame points (..., 3) to the model frame."""
        return (p_w - self.t_w) @ self.R_w

    def is_face(self, p_model: np.ndarray) -> np.ndarray:
        """Points (..., 3, model frame) in front of the ears and above the chin."""
        return (p_model[..., 2] > self.ear_z + FRONT_MM) & (p_model[..., 1] > self.chin_y - 5.0)

    def camera(self, yaw_deg: float, pitch_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """Camera-to-scanner rotation and centre of a camera aimed at the face.

        The camera looks at a point 40 mm behind the nose tip, halfway between chin and
        crown, from ``DISTANCE_MM``, its direction turned by yaw (about the model's up axis)
        and pitch. Camera axes are OpenCV's: x right, y down, z forward.
        """
        target = np.array([self.nose[0], 0.5 * (self.chin_y + self.crown_y), self.nose[2] - 40.0])
        rot = Rotation.from_euler("yx", [yaw_deg, pitch_deg], degrees=True).as_matrix()
        back = rot @ np.array([0.0, 0.0, 1.0])
        forward = -back
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        R_cm = np.stack([right, down, forward], axis=1)
        centre = target + DISTANCE_MM * back
        return self.R_w @ R_cm, self.R_w @ centre + self.t_w

    def focal_px(self) -> float:
        """Focal length (px) that makes the head fill ``FACE_FILL`` of the image height."""
        return FACE_FILL * HEIGHT * DISTANCE_MM / (self.crown_y - self.chin_y)

    def cast(self, origin: np.ndarray, dirs: np.ndarray) -> dict[str, np.ndarray]:
        """Cast scanner-frame rays ``origin + t dirs``; exact float64 hits.

        Returns ``t`` (..., NaN on a miss, in units of ``|dirs|``), ``face`` (..., -1 on a
        miss), ``bary`` (..., 3) barycentric weights of the hit's triangle vertices.
        """
        shape = dirs.shape[:-1]
        d = dirs.reshape(-1, 3)
        rays = np.concatenate([np.broadcast_to(origin, d.shape), d], axis=1)
        ans = self.scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)), nthreads=2)
        pid = ans["primitive_ids"].numpy()
        hit = pid != o3d.t.geometry.RaycastingScene.INVALID_ID
        face = np.where(hit, pid.astype(np.int64), -1)
        # exact hit: the ray against the plane of the triangle open3d found
        tri = self.vertices_w[self.faces[face[hit]]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        t = np.full(d.shape[0], np.nan)
        t[hit] = np.einsum("ij,ij->i", normal, tri[:, 0] - origin) / np.einsum(
            "ij,ij->i", normal, d[hit]
        )
        uv = ans["primitive_uvs"].numpy().astype(np.float64)
        bary = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
        return {
            "t": t.reshape(shape),
            "t_o3d": np.where(hit, ans["t_hit"].numpy(), np.nan).reshape(shape),
            "face": face.reshape(shape),
            "bary": bary.reshape(shape + (3,)),
        }

    def interpolate(self, values: np.ndarray, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """Per-vertex ``values`` (V, C) at hits (face (...), bary (..., 3)); 0 on a miss."""
        f = self.faces[np.maximum(face, 0)]  # (..., 3)
        out = np.einsum("...k,...kc->...c", bary, values[f])
        return np.where((face >= 0)[..., None], out, 0.0)


def _raycasting_scene(vertices_w: np.ndarray, faces: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    """An open3d ray-casting scene of a triangle mesh (vertices (V, 3) mm, faces (F, 3))."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(vertices_w.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32))
    )
    return scene


def _moved(head: Head, vertices: np.ndarray) -> Head:
    """The head with its vertices moved to ``vertices`` (V, 3), model frame, mm (an expression):
    its scanner-frame vertices, ray-casting scene and normals to match."""
    import dataclasses

    from scan2morph.geometry import vertex_normals

    moved_w = vertices @ head.R_w.T + head.t_w
    return dataclasses.replace(
        head, vertices=vertices, vertices_w=moved_w, scene=_raycasting_scene(moved_w, head.faces),
        normals=vertex_normals(vertices, head.faces),
    )  # fmt: skip


@pytest.fixture(scope="module")
def head() -> Head:
    return load_head()


def load_head() -> Head:
    """The scan, scaled to mm, in its model frame and a seeded random scanner frame."""
    t0 = time.perf_counter()
    mesh = trimesh.load(GLB, force="mesh")
    units = np.asarray(mesh.vertices, dtype=np.float64)
    head_band = units[:, 1] > NECK_TOP_UNITS
    mm_per_unit = HEAD_WIDTH_MM / float(np.ptp(units[head_band, 0]))
    v = units * mm_per_unit
    uv = np.asarray(mesh.visual.uv, dtype=np.float64).copy()
    uv[:, 1] = 1.0 - uv[:, 1]
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    texture = cv2.cvtColor(cv2.imread(str(COLOR_MAP), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    faces = np.asarray(mesh.faces, dtype=np.int64)

    nose = v[np.argmax(v[:, 2])]
    band = np.flatnonzero(head_band)
    ears = band[[np.argmin(v[band, 0]), np.argmax(v[band, 0])]]
    ear_z = float(v[ears, 2].mean())
    crown_y = float(v[:, 1].max())
    chin_y = float(v[v[:, 2] > nose[2] - 25.0, 1].min())  # lowest point near the front

    rng = np.random.default_rng(SEED)
    R_w = Rotation.random(rng=rng).as_matrix()
    t_w = rng.uniform(-500.0, 500.0, 3)
    v_w = v @ R_w.T + t_w
    scene = _raycasting_scene(v_w, faces)
    print(
        f"\n[realdata] mesh {len(v)} vertices / {len(faces)} faces, {mm_per_unit:.2f} mm per "
        f"unit; head {np.ptp(v[head_band, 0]):.0f} mm wide, chin to crown "
        f"{crown_y - chin_y:.0f} mm, nose tip {nose[2] - ear_z:.0f} mm in front of the ears "
        f"(load {time.perf_counter() - t0:.2f} s)"
    )
    return Head(
        v,
        faces,
        uv,
        normals,
        texture,
        mm_per_unit,
        nose,
        ear_z,
        chin_y,
        crown_y,
        R_w,
        t_w,
        scene,
        v_w,
    )


# --------------------------------------------------------------------------------------------
# an organised range image of it


@dataclass
class RangeScan:
    """Ray-cast range image and its per-pixel truth."""

    xyz: np.ndarray  # (H, W, 3) scanner frame, mm, NaN = miss (the take's frame)
    xyz_cam: np.ndarray  # (H, W, 3) camera frame, mm
    rays: np.ndarray  # (H, W, 3) unit rays, scanner frame
    face: np.ndarray  # (H, W) bool, pixel sees the face (in front of the ears, above chin)
    valid: np.ndarray  # (H, W) bool
    K: np.ndarray


@pytest.fixture(scope="module")
def range_scan(head) -> RangeScan:
    t0 = time.perf_counter()
    R_cw, centre = head.camera(yaw_deg=10.0, pitch_deg=5.0)
    f = head.focal_px()
    K = np.array([[f, 0.0, 0.5 * (WIDTH - 1)], [0.0, f, 0.5 * (HEIGHT - 1)], [0.0, 0.0, 1.0]])
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    d_cam = np.stack([(xs - K[0, 2]) / f, (ys - K[1, 2]) / f, np.ones_like(xs)], axis=-1)
    d_w = d_cam @ R_cw.T
    hit = head.cast(centre, d_w)
    t = hit["t"]  # depth along the optical axis (|d_cam| has z = 1)
    valid = np.isfinite(t)
    xyz = centre + t[..., None] * d_w
    xyz_cam = t[..., None] * d_cam
    face = valid & head.is_face(head.to_model(np.where(valid[..., None], xyz, 0.0)))
    rays = d_w / np.linalg.norm(d_w, axis=-1, keepdims=True)
    # open3d's float32 hit agrees with the float64 one on the same triangle (measured: median
    # 5e-5 mm, 99th percentile 4e-4 mm, worst 9e-3 mm at grazing incidence)
    gap = np.abs(t - hit["t_o3d"])[valid]
    assert np.percentile(gap, 99) < 1e-3 and gap.max() < 0.05
    rows = np.flatnonzero(face.any(axis=1))
    print(
        f"[realdata] range scan {WIDTH}x{HEIGHT}, f = {f:.0f} px, {valid.mean():.1%} of pixels "
        f"hit, face {face.sum()} px over {np.ptp(rows) + 1} rows, depth "
        f"{np.nanmin(xyz_cam[..., 2]):.0f}-{np.nanmax(xyz_cam[..., 2]):.0f} mm "
        f"({time.perf_counter() - t0:.2f} s)"
    )
    return RangeScan(xyz, xyz_cam, rays, face, valid, K)


def test_range_scan_matches_its_specification(head, range_scan):
    """The scene is what the docstring says: scale, framing, projection, frame independence."""
    assert range_scan.face.sum() > 30000
    # the head (chin to crown) fills about FACE_FILL of the image height
    model = head.to_model(np.where(range_scan.valid[..., None], range_scan.xyz, 0.0))
    rows = np.flatnonzero((range_scan.valid & (model[..., 1] > head.chin_y)).any(axis=1))
    assert abs((np.ptp(rows) + 1) / HEIGHT - FACE_FILL) < 0.1
    # every truth point projects onto its own pixel centre (OpenCV as the oracle)
    ys, xs = np.nonzero(range_scan.valid)
    pts = np.ascontiguousarray(range_scan.xyz_cam[ys, xs]).reshape(-1, 1, 3)
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), range_scan.K, np.zeros(5))
    np.testing.assert_allclose(proj[:, 0], np.stack([xs, ys], axis=1), atol=1e-7)
    # the scanner frame is a rigid motion of the camera frame (distances agree)
    a = range_scan.xyz[ys[::97], xs[::97]]
    b = range_scan.xyz_cam[ys[::97], xs[::97]]
    np.testing.assert_allclose(
        np.linalg.norm(a[1:] - a[:-1], axis=1), np.linalg.norm(b[1:] - b[:-1], axis=1), atol=1e-9
    )


# --------------------------------------------------------------------------------------------
# 1. range repair


def _ellipse(shape, centre, area, aspect, angle) -> np.ndarray:
    """(H, W) bool mask of a filled ellipse of about ``area`` px."""
    a = np.sqrt(area * aspect / np.pi)
    b = np.sqrt(area / (aspect * np.pi))
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]]
    dx, dy = xs - centre[1], ys - centre[0]
    c, s = np.cos(angle), np.sin(angle)
    return ((c * dx + s * dy) / a) ** 2 + ((-s * dx + c * dy) / b) ** 2 <= 1.0


def _punch_blobs(allowed, areas, rng, area_range):
    """Non-overlapping elliptical blobs inside ``allowed``, one per target area."""
    blobs = []
    taken = np.zeros_like(allowed)
    candidates = np.argwhere(allowed)
    for target in areas:
        for _ in range(200):  # rejection sampling over a handful of blobs
            centre = candidates[rng.integers(len(candidates))]
            blob = _ellipse(
                allowed.shape, centre, target, rng.uniform(1.0, 2.5), rng.uniform(0, np.pi)
            )
            n = int(blob.sum())
            grown = ndimage.binary_dilation(blob, iterations=4)
            if area_range[0] <= n <= area_range[1] and not (grown & (taken | ~allowed)).any():
                blobs.append(blob)
                taken |= grown
                break
        else:
            raise AssertionError(f"could not place a blob of {target} px")
    return blobs


def _rms(err: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(err**2, axis=-1))))


def _depth_steps(depth: np.ndarray, step_mm: float = 3.0) -> np.ndarray:
    """(H, W) bool: valid pixels next to a depth step.

    ``depth`` is (H, W) mm, NaN where there is no surface. A pixel is marked when a
    4-neighbour's depth differs by more than ``step_mm`` or is missing (the silhouette); both
    sides of a step are marked.
    """
    valid = np.isfinite(depth)
    d = np.where(valid, depth, 1e9)  # background: a step
    steps = np.zeros(d.shape, bool)
    for axis in (0, 1):
        step = ~(np.abs(np.diff(d, axis=axis)) < step_mm)
        lo = [slice(None), slice(None)]
        hi = [slice(None), slice(None)]
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        steps[tuple(lo)] |= step
        steps[tuple(hi)] |= step
    return steps & valid


def test_repair_on_real_geometry(range_scan):
    """Spikes, small holes and a large hole on the real face, against the noise-free truth."""
    rng = np.random.default_rng(SEED + 1)
    truth, valid, rays = range_scan.xyz, range_scan.valid, range_scan.rays
    noisy = truth + NOISE_MM * rng.standard_normal(valid.shape)[..., None] * rays

    # holes only on smooth skin: away from depth discontinuities (nose side, ears, lip line,
    # silhouette), entirely inside the face
    jump = _depth_steps(np.where(valid, range_scan.xyz_cam[..., 2], np.nan))
    smooth = ndimage.binary_erosion(range_scan.face, iterations=15) & ~ndimage.binary_dilation(
        jump, iterations=20
    )
    small = _punch_blobs(smooth, [12, 25, 50, 80, 120, 160, 200], rng, (10, 200))
    holes = np.logical_or.reduce(small)
    max_hole = int(DEFAULT_REPAIR["max_hole_px"])
    (big,) = _punch_blobs(smooth & ~holes, [2 * max_hole], rng, (max_hole + 100, 4 * max_hole))

    # spikes: 0.1 % of the valid pixels, 20-50 mm along the ray (either way), where the truth
    # is locally smooth (a full spike window without a depth step) and away from the holes
    win = int(DEFAULT_REPAIR["spike_window"])
    eligible = (
        ndimage.binary_erosion(valid, np.ones((win, win)), border_value=0)
        & ~ndimage.binary_dilation(jump, iterations=win // 2)
        & ~ndimage.binary_dilation(holes | big, iterations=win)
    )
    n_spikes = int(round(1e-3 * valid.sum()))
    pick = rng.choice(np.flatnonzero(eligible), n_spikes, replace=False)
    spike = np.zeros_like(valid)
    spike.flat[pick] = True
    offset = rng.choice([-1.0, 1.0], n_spikes) * rng.uniform(20.0, 50.0, n_spikes)
    scan = noisy.copy()
    scan.reshape(-1, 3)[pick] += offset[:, None] * rays.reshape(-1, 3)[pick]
    scan[holes | big] = np.nan

    t0 = time.perf_counter()
    out, report = repair_range(scan, dict(DEFAULT_REPAIR), source="lee-perry-smith/range")
    t_repair = time.perf_counter() - t0

    # every spike beyond 3x the threshold is gone
    threshold = float(DEFAULT_REPAIR["spike_threshold_mm"])
    assert np.all(np.abs(offset) > 3 * threshold)
    assert report["spikes"][spike].all()
    # true pixels taken for spikes lie only at depth steps: the grazing rim of the silhouette
    # and thin features (a ray through the lip line hits the mouth 70 mm deeper)
    false_spikes = report["spikes"] & ~spike
    assert not (false_spikes & ~jump).any()
    n_rim = int((false_spikes & ndimage.binary_dilation(~valid)).sum())

    # small holes filled close to the noise-free truth; the large one stays NaN
    assert np.isfinite(out[holes]).all() and report["filled"][holes].all()
    assert np.isnan(out[big]).all() and not report["filled"][big].any()
    assert int(big.sum()) in report["unfilled_holes"]
    rms_holes = _rms(out[holes] - truth[holes])
    max_holes = float(np.linalg.norm(out[holes] - truth[holes], axis=-1).max())
    per_hole = [_rms(out[h] - truth[h]) for h in small]
    assert np.isfinite(out[spike]).all()
    rms_spikes = _rms(out[spike] - truth[spike])
    kept = np.isfinite(scan[..., 0]) & ~report["spikes"]
    rms_kept = _rms(out[kept] - truth[kept])

    # cv2.inpaint on the same input (the spike-cleaned scan) and mask, per float32 coordinate
    clean = np.where(report["spikes"][..., None], np.nan, scan)
    mask = report["filled"].astype(np.uint8)
    rms_cv = {}
    for name, flag in (("Telea", cv2.INPAINT_TELEA), ("NS", cv2.INPAINT_NS)):
        filled = np.empty_like(truth)
        for c in range(3):
            src = np.nan_to_num(clean[..., c], nan=0.0).astype(np.float32)
            filled[..., c] = cv2.inpaint(src, mask, 3, flag)
        rms_cv[name] = _rms(filled[holes] - truth[holes])

    print(
        f"\n[realdata] repair_range ({t_repair:.2f} s, {valid.sum()} valid px, noise "
        f"{NOISE_MM} mm): {n_spikes} spikes of 20-50 mm all removed; "
        f"{int(false_spikes.sum())} true pixels also removed, all at depth steps ({n_rim} on the "
        f"silhouette rim); {len(small)} holes of {min(int(h.sum()) for h in small)}-"
        f"{max(int(h.sum()) for h in small)} px ({int(holes.sum())} px) filled to RMS "
        f"{rms_holes:.3f} mm (max {max_holes:.3f}; per hole "
        f"{', '.join(f'{r:.3f}' for r in per_hole)}); spike pixels refilled to RMS "
        f"{rms_spikes:.3f} mm; untouched pixels RMS {rms_kept:.3f} mm (the noise); "
        f"{int(big.sum())} px hole left NaN; cv2.inpaint on the same holes: RMS Telea "
        f"{rms_cv['Telea']:.3f} mm, NS {rms_cv['NS']:.3f} mm"
    )
    # Bounds (measured 0.10 mm for the holes, 0.06 for the spike pixels): a filled pixel is a
    # smoothed extrapolation of rim samples that each carry 0.1 mm noise, and the per-hole
    # quadratic trend follows the face's curvature over these <= 200 px (~8 mm) holes.
    assert rms_holes < 0.2 and max_holes < 0.6
    assert rms_spikes < 0.15
    assert rms_holes < 0.25 * min(rms_cv.values())


# --------------------------------------------------------------------------------------------
# 2. stereo


SPECKLE_MM = 1.0  # projected speckle cell at the face (~1.6 px)
PATTERN_PX = 1024  # projector pattern side, px


@dataclass
class StereoPair:
    left: np.ndarray
    right: np.ndarray
    calib: StereoCalibration
    xyz: np.ndarray  # (H, W, 3) truth of every left pixel centre, left camera frame, mm
    face: np.ndarray  # (H, W) bool, left pixel sees the face
    front: np.ndarray  # face, seen within 60 degrees of the surface normal
    render_s: float
    texture: np.ndarray | None = None  # the left camera's texture shot (no speckle), if asked


def _rig(head: Head) -> list[dict]:
    """Both cameras (K, D, camera-to-scanner R, centre C) and the projector pose."""
    R_rig, centre = head.camera(yaw_deg=-12.0, pitch_deg=-4.0)
    f = head.focal_px()
    cx, cy = 0.5 * (WIDTH - 1), 0.5 * (HEIGHT - 1)
    toe = np.deg2rad(TOE_IN_DEG)
    roll = Rotation.from_euler("x", 0.004).as_matrix()  # a real rig is never perfect
    return [
        {
            "K": np.array([[f, 0.0, cx + 3.2], [0.0, 1.002 * f, cy - 2.1], [0.0, 0.0, 1.0]]),
            "D": np.array([-0.05, 0.01, 0.0, 0.0, 0.0]),
            "R": R_rig @ Rotation.from_euler("y", toe).as_matrix(),
            "C": centre - 0.5 * BASELINE_MM * R_rig[:, 0],
        },
        {
            "K": np.array(
                [[1.005 * f, 0.0, cx - 4.0], [0.0, 1.006 * f, cy + 1.5], [0.0, 0.0, 1.0]]
            ),
            "D": np.array([-0.045, 0.0, 0.0005, -0.0003, 0.0]),
            "R": R_rig @ Rotation.from_euler("y", -toe).as_matrix() @ roll,
            "C": centre + R_rig @ np.array([0.5 * BASELINE_MM, 0.8, -1.5]),
        },
        {"R": R_rig, "C": centre},  # projector and light
    ]


def _shade(head: Head, hit: dict, points: np.ndarray, rig: list[dict], pattern: np.ndarray | None):
    """Intensity (..., 3) of scanner-frame surface points: colour map x speckle x Lambert
    (``pattern`` None: the projector off, a texture shot: colour map x Lambert)."""
    face, bary = hit["face"], hit["bary"]
    miss = face < 0
    uv = head.interpolate(head.uv, face, bary)
    col = (uv[..., 0] * head.texture.shape[1] - 0.5).astype(np.float32)
    row = ((1.0 - uv[..., 1]) * head.texture.shape[0] - 0.5).astype(np.float32)
    flat = (uv.shape[0], -1)  # cv2.remap takes 2-D maps
    colour = cv2.remap(
        head.texture,
        col.reshape(flat),
        row.reshape(flat),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REFLECT,
    ).reshape(uv.shape[:-1] + (3,))
    proj = rig[2]
    light = proj["C"] - points  # Lambert shading from the rig centre
    light /= np.maximum(np.linalg.norm(light, axis=-1, keepdims=True), 1e-12)
    normal = head.interpolate(head.normals, face, bary) @ head.R_w.T
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    shade = 0.6 + 0.4 * np.clip(np.sum(normal * light, axis=-1), 0.0, 1.0)
    if pattern is None:
        return np.where(miss[..., None], 0.0, shade[..., None] * colour)
    # speckle projected from the rig centre (no projector shadows): view independent
    p = (points - proj["C"]) @ proj["R"]
    f_proj = DISTANCE_MM / SPECKLE_MM
    u = f_proj * p[..., 0] / p[..., 2] + 0.5 * (PATTERN_PX - 1)
    v = f_proj * p[..., 1] / p[..., 2] + 0.5 * (PATTERN_PX - 1)
    speckle = ndimage.map_coordinates(pattern, [v.ravel(), u.ravel()], order=1, mode="nearest")
    value = shade[..., None] * (0.35 * colour + 0.65 * speckle.reshape(shade.shape)[..., None])
    return np.where(miss[..., None], 0.0, value)


def render_stereo_pair(
    head: Head, seed: int = SEED + 2, rig: list | None = None, texture_shot: bool = False
) -> StereoPair:
    """The head seen by the test rig (:func:`_rig`, or ``rig``: a rig that stays where it was
    while the head moves): both images (2 x 2 supersampled, the projected speckle over the
    colour map, 1 grey level of sensor noise; ``seed``), the calibration and the left pixels'
    truth; with ``texture_shot`` also the left camera's view with the projector off."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    pattern = ndimage.gaussian_filter(rng.random((PATTERN_PX, PATTERN_PX)), 0.6)
    pattern = np.clip(128.0 + 55.0 * (pattern - pattern.mean()) / pattern.std(), 5.0, 250.0)
    rig = _rig(head) if rig is None else rig
    sub = np.array([-0.25, 0.25])
    ys, xs, dy, dx = np.meshgrid(np.arange(HEIGHT), np.arange(WIDTH), sub, sub, indexing="ij")
    values = []  # left, right, and the texture shot: the left camera's rays lit without speckle
    for cam in rig[:2]:
        rays = pixel_rays(xs + dx, ys + dy, cam["K"], cam["D"]) @ cam["R"].T  # (H, W, 2, 2, 3)
        hit = head.cast(cam["C"], rays)
        points = cam["C"] + np.nan_to_num(hit["t"])[..., None] * rays
        lights = [pattern, None] if texture_shot and cam is rig[0] else [pattern]
        values += [_shade(head, hit, points, rig, lit).mean(axis=(2, 3)) for lit in lights]
    if texture_shot:
        values.append(values.pop(1))  # the images' noise is drawn left, right, shot
    images = []
    for value in values:
        value += rng.standard_normal(value.shape[:2])[..., None]  # 1 grey level sensor noise
        images.append(np.clip(np.rint(value), 0, 255).astype(np.uint8))

    left, right = rig[0], rig[1]
    R = right["R"].T @ left["R"]
    T = right["R"].T @ (left["C"] - right["C"])
    calib = StereoCalibration(left["K"], left["D"], right["K"], right["D"], R, T, (WIDTH, HEIGHT))

    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    rays_cam = pixel_rays(xs, ys, left["K"], left["D"])  # unit: t is the range
    rays_w = rays_cam @ left["R"].T
    hit = head.cast(left["C"], rays_w)
    valid = np.isfinite(hit["t"])
    xyz = np.where(valid[..., None], hit["t"][..., None] * rays_cam, np.nan)
    points = left["C"] + np.nan_to_num(hit["t"])[..., None] * rays_w
    face = valid & head.is_face(head.to_model(points))
    normal = head.interpolate(head.normals, hit["face"], hit["bary"]) @ head.R_w.T
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    front = face & (-np.sum(normal * rays_w, axis=-1) > np.cos(np.deg2rad(60.0)))
    render_s = time.perf_counter() - t0
    texture = images[2] if texture_shot else None
    return StereoPair(images[0], images[1], calib, xyz, face, front, render_s, texture)


@pytest.fixture(scope="module")
def stereo_pair(head) -> StereoPair:
    return render_stereo_pair(head)


def test_stereo_on_real_geometry(stereo_pair):
    """Depth accuracy and coverage of the stereo reconstruction of the real face."""
    pair = stereo_pair
    # the rendered truth projects onto its own (distorted) left pixels: OpenCV as the oracle
    ys, xs = np.nonzero(np.isfinite(pair.xyz[..., 2]))
    pts = np.ascontiguousarray(pair.xyz[ys, xs]).reshape(-1, 1, 3)
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), pair.calib.K1, pair.calib.D1)
    np.testing.assert_allclose(proj[:, 0], np.stack([xs, ys], axis=1), atol=1e-7)
    depth = pair.xyz[pair.face, 2]
    params = {"min_depth_mm": 650.0, "max_depth_mm": 1100.0}
    assert params["min_depth_mm"] < depth.min() and depth.max() < params["max_depth_mm"]

    t0 = time.perf_counter()
    xyz, report = reconstruct_stereo(
        pair.left, pair.right, pair.calib, params, source="lee-perry-smith/stereo"
    )
    t_stereo = time.perf_counter() - t0

    # error of every left pixel: both points lie on its ray, so this is the range error
    # (at least the depth error)
    err_all = np.linalg.norm(xyz - pair.xyz, axis=-1)
    steps = _depth_steps(pair.xyz[..., 2])
    near_step = ndimage.binary_dilation(steps, iterations=3)  # within 3 px of a depth step
    regions = {
        "face": pair.face,
        "face off steps": pair.face & ~near_step,
        "front": pair.front,
        "step bands": pair.face & near_step,
    }
    stats = {}
    for name, region in regions.items():
        err = err_all[region]
        ok = np.isfinite(err)
        stats[name] = {
            "coverage": float(ok.mean()),
            "rms": float(np.sqrt(np.mean(err[ok] ** 2))),
            "p99": float(np.percentile(err[ok], 99)),
            "max": float(err[ok].max()),
            "n": int(region.sum()),
        }
    # points where the left pixel sees only the (black, untextured) background
    truth_valid = np.isfinite(pair.xyz[..., 2])
    stray = np.isfinite(xyz[..., 2]) & ~truth_valid
    stray_px = ndimage.distance_transform_edt(~truth_valid)[stray]
    print(
        f"\n[realdata] stereo: render {pair.render_s:.2f} s, reconstruct_stereo {t_stereo:.2f} s "
        f"(f {pair.calib.K1[0, 0]:.0f} px, baseline {report['baseline_mm']:.1f} mm, face at "
        f"{depth.min():.0f}-{depth.max():.0f} mm, disparities {report['minDisparity']}+"
        f"{report['numDisparities']}, image coverage {report['coverage']:.1%}); "
        + "; ".join(
            f"{k} ({v['n']} px): coverage {v['coverage']:.1%}, RMS {v['rms']:.3f} mm, "
            f"p99 {v['p99']:.2f} mm, max {v['max']:.1f} mm"
            for k, v in stats.items()
        )
        + f"; {int(stray.sum())} points off the silhouette on background pixels (up to "
        f"{stray_px.max():.0f} px out)"
    )
    # Measured: face 0.64 mm / 91 %, off the step bands 0.37 mm / 97 %, front 0.35 mm /
    # 99.7 %, step bands 3.1 mm. The synthetic target (0.5 mm) holds wherever the surface is
    # continuous over the matching window; along the nose rim, the ears and the silhouette
    # (the 3 px bands) window matching mixes the two sides of the step.
    assert stats["front"]["rms"] < 0.5 and stats["front"]["coverage"] > 0.99
    assert stats["face off steps"]["rms"] < 0.5 and stats["face off steps"]["coverage"] > 0.95
    assert stats["face"]["rms"] < 0.7 and stats["face"]["coverage"] > 0.88
    # Known weakness (reported): against an untextured background the silhouette is not a
    # disparity discontinuity, so the edge trim does not remove the foreground-fattened band
    # (measured 2347 points, up to 6 px outside the head). Guard against it growing.
    assert stray.sum() < 3000 and stray_px.max() <= 8


# --------------------------------------------------------------------------------------------
# 3. modal basis


@pytest.fixture(scope="module")
def face_mesh(head) -> dict:
    """The face in front of the ears, UV seams welded, largest connected part, cleaned."""
    # weld: the GLB splits vertices along UV seams (15 pieces); positions are shared exactly
    pos, inverse = np.unique(head.vertices, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[head.faces]
    inside = head.is_face(pos)
    cut = trimesh.Trimesh(pos, faces[inside[faces].all(axis=1)], process=False)
    pieces = cut.split(only_watertight=False)
    part = max(pieces, key=lambda m: len(m.faces))
    v = np.asarray(part.vertices, dtype=np.float64)
    f = np.asarray(part.faces, dtype=np.int64)
    min_area = float(np.asarray(part.area_faces).min())
    try:
        check_mesh(v, f, "lee-perry-smith/face")
        refused = None
    except InputError as exc:  # degenerate triangles: say which, then clean
        refused = str(exc)
    keep = part.nondegenerate_faces()
    part.update_faces(keep)
    part.remove_unreferenced_vertices()
    return {
        "min_area_mm2": min_area,
        "vertices": np.asarray(part.vertices, dtype=np.float64),
        "faces": np.asarray(part.faces, dtype=np.int64),
        "n_pieces": len(pieces),
        "n_welded": len(head.vertices) - len(pos),
        "refused": refused,
        "removed_faces": int((~keep).sum()),
    }


def test_modal_basis_on_real_geometry(face_mesh):
    """Mass-orthonormal modes with ascending frequencies; a 3-mode field projects exactly."""
    v, f = face_mesh["vertices"], face_mesh["faces"]
    t0 = time.perf_counter()
    basis = modal_basis(v, f, ModalParams(n_modes=20), source="lee-perry-smith/face")
    t_modal = time.perf_counter() - t0

    q, m, k = basis.vectors, basis.mass, basis.stiffness
    assert q.shape == (DOF * len(v), 20)
    gram = q.T @ (m @ q)
    assert np.abs(gram - np.eye(20)).max() < 1e-8
    freqs = basis.frequencies_hz
    assert freqs[0] > 0 and np.all(np.diff(freqs) >= 0)
    # they are eigenpairs: K q = omega^2 M q on the free DOFs
    free = np.repeat(~basis.fixed_vertices, DOF)
    omega2 = (2.0 * np.pi * freqs) ** 2
    resid = (k @ q - (m @ q) * omega2)[free]
    rel = np.linalg.norm(resid, axis=0) / np.linalg.norm((k @ q)[free], axis=0)
    assert rel.max() < 1e-6
    # independent oracle: scipy's ARPACK (shift-invert at 0) for the lowest six
    kf = sp.csc_matrix(k)[free][:, free]
    mf = sp.csc_matrix(m)[free][:, free]
    t1 = time.perf_counter()
    lam = sla.eigsh(kf, k=6, M=mf, sigma=0.0, which="LM", return_eigenvectors=False)
    t_arpack = time.perf_counter() - t1
    np.testing.assert_allclose(np.sqrt(np.sort(lam)) / (2 * np.pi), freqs[:6], rtol=1e-8)

    # a displacement field made of three known modes (full DOF vectors) is recovered exactly
    coords = np.zeros(20)
    coords[[1, 6, 14]] = [0.03, -0.02, 0.012]  # mm sqrt(tonne)
    field = np.einsum("k,kvd->vd", coords, basis.dof_modes)
    got = project(basis, field, source="lee-perry-smith/face")
    assert np.abs(got - coords).max() < 1e-8
    np.testing.assert_allclose(reconstruct(basis, got), field[:, :3], atol=1e-9)

    print(
        f"\n[realdata] modal: face cut {len(v)} vertices / {len(f)} triangles "
        f"({face_mesh['n_welded']} seam vertices welded, {face_mesh['n_pieces']} piece(s) "
        f"after the cut, {int(basis.fixed_vertices.sum())} boundary vertices clamped); "
        f"smallest triangle {face_mesh['min_area_mm2']:.2g} mm^2, check_mesh: "
        f"{face_mesh['refused'] or 'accepted'}; {face_mesh['removed_faces']} "
        f"degenerate faces removed; 20 modes {freqs[0]:.1f}-{freqs[-1]:.1f} Hz in "
        f"{t_modal:.2f} s (scipy eigsh, 6 modes: {t_arpack:.2f} s); max |Q^T M Q - I| "
        f"{np.abs(gram - np.eye(20)).max():.1e}, max relative residual {rel.max():.1e}, "
        f"projection error {np.abs(got - coords).max():.1e}"
    )


# --------------------------------------------------------------------------------------------
# rigid alignment of a smiling take on the real face's shape


def test_alignment_grows_into_the_still_skin_of_a_real_face(head):
    """The stable region (forehead, nose ridge, temples, placed by measure from the nose tip)
    of the real face constrains a smiling take's rotation only to about 0.2 degrees under
    0.1 mm noise; grown into the upper face's still skin, to < 0.1 degrees. The take smiles (cheeks, lower
    temples, mouth corners) and is moved by a random 5 degree / 10 mm motion."""
    from scan2morph.align import (
        AlignMeshes,
        IcpParams,
        align_take,
        invert,
        rotation_angle_deg,
        transform_points,
    )

    v = head.vertices
    x, y = v[:, 0] - head.nose[0], v[:, 1] - head.nose[1]
    face = head.is_face(v)
    region = face & (
        (y > 55) | ((np.abs(x) < 8) & (y > 10) & (y < 45)) | ((np.abs(x) > 50) & (y > 10))
    )
    upper = np.flatnonzero(face & (y > 0))
    pairs = np.array(
        [
            np.argmin(np.where(face, np.hypot(x - a, y - b), np.inf))
            for a, b in [(-35, 32), (35, 32), (0, 30), (-15, 32), (15, 32), (0, 75)]
        ]
    )
    centre = v[region].mean(axis=0)
    errors = {"alone": [], "grown": []}
    for seed in range(5):
        rng = np.random.default_rng(SEED + seed)
        truth = np.eye(4)  # take scanner frame -> neutral (model) frame
        axis = rng.normal(size=3)
        truth[:3, :3] = Rotation.from_rotvec(
            np.radians(5.0) * axis / np.linalg.norm(axis)
        ).as_matrix()
        truth[:3, 3] = rng.normal(scale=6.0, size=3)
        take = transform_points(invert(truth), v + smile_displacement(x, y))
        take += rng.normal(scale=NOISE_MM, size=v.shape)
        take[pairs] += rng.normal(scale=1.0, size=(len(pairs), 3))  # clicked, not exact
        for name, grow in (("alone", None), ("grown", upper)):
            res = align_take(
                AlignMeshes(take, face, v, face, head.faces),
                pairs,
                np.flatnonzero(region),
                IcpParams(kernel_k_mm=0.3),  # as config/config.yaml
                source="lee-perry-smith/smile",
                grow_indices=grow,
            )
            assert res.ok, (name, res.problems)
            e = res.transform @ invert(truth)
            shift = np.linalg.norm(transform_points(e, centre) - centre)
            errors[name].append((rotation_angle_deg(e), shift))
    grown, alone = np.array(errors["grown"]), np.array(errors["alone"])
    assert grown[:, 0].max() < 0.1 and grown[:, 1].max() < 0.1, grown
    assert alone[:, 0].max() > 1.5 * grown[:, 0].max(), (alone, grown)
    print(
        f"\n[realdata] align (smile, 5 seeds): region alone {alone[:, 0].max():.3f} deg / "
        f"{alone[:, 1].max():.3f} mm worst; grown into the upper face {grown[:, 0].max():.3f} "
        f"deg / {grown[:, 1].max():.3f} mm"
    )


# --------------------------------------------------------------------------------------------
# the jaw prior's registration of a turned chin on the real face's shape


def _cast_mesh(vertices_w, faces, origin, dirs):
    """Scanner-frame hits of rays ``origin + t dirs`` (H, W, 3) on a mesh; NaN on a miss."""
    scene = _raycasting_scene(vertices_w, faces)
    d = dirs.reshape(-1, 3)
    rays = np.concatenate([np.broadcast_to(origin, d.shape), d], axis=1).astype(np.float32)
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    t = np.where(np.isfinite(t), t, np.nan).reshape(dirs.shape[:-1])
    return origin + t[..., None] * dirs


@pytest.mark.parametrize("pout_mm", [0.0, 2.0])
def test_jaw_registration_on_a_real_chin(head, pout_mm):
    """The real chin turned 10 degrees with the jaw (about a hinge in front of the ears, fading
    out above the lower lip) and scanned with 0.1 mm noise: from a pose 6 mm off (a slid fit)
    its registration to the take's surface lands within a third of a millimetre, and its shape
    pins its motion (scan2morph.refine.jaw.MIN_CONSTRAINT); a pout that pushes part of the chin
    out by ``pout_mm`` fails the rigidity gate the still forehead sets."""
    from scan2morph.align import IcpParams, region_motion, transform_points
    from scan2morph.align.noise import robust_rms
    from scan2morph.refine.jaw import MIN_CONSTRAINT, scan_surface

    rng = np.random.default_rng(SEED + 7)
    v = head.vertices
    x, y = v[:, 0] - head.nose[0], v[:, 1] - head.nose[1]
    face = head.is_face(v)
    follow = np.clip((-y - 38.0) / 14.0, 0.0, 1.0)[:, None]  # the jaw's share
    hinge = np.array([head.nose[0], head.nose[1] - 15.0, head.ear_z + 10.0])
    jaw = np.eye(4)
    jaw[:3, :3] = Rotation.from_euler("x", 10.0, degrees=True).as_matrix()  # chin down, back
    jaw[:3, 3] = hinge - jaw[:3, :3] @ hinge
    moved = (1 - follow) * v + follow * transform_points(jaw, v)
    moved[:, 2] += pout_mm * np.exp(-((x + 12) ** 2 + (y + 62) ** 2) / 200.0)
    # the take, scanned as the range scan is: its frame is the scanner's
    R_cw, centre = head.camera(yaw_deg=10.0, pitch_deg=5.0)
    f = head.focal_px()
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    d_cam = np.stack(
        [(xs - 0.5 * (WIDTH - 1)) / f, (ys - 0.5 * (HEIGHT - 1)) / f, np.ones_like(xs)], -1
    )
    xyz = _cast_mesh(moved @ head.R_w.T + head.t_w, head.faces, centre, d_cam @ R_cw.T)
    xyz += rng.normal(scale=NOISE_MM, size=xyz.shape) * (d_cam @ R_cw.T)
    to_model = np.eye(4)  # scanner -> model (the neutral's frame)
    to_model[:3, :3], to_model[:3, 3] = head.R_w.T, -head.R_w.T @ head.t_w
    chin = face & (follow[:, 0] >= 1.0) & (y > -95.0) & (np.abs(x) < 25.0)
    chin &= (v - head.nose) @ [0.0, 0.0, 1.0] > -45.0  # the front of the chin, not under it
    region = v[chin] + rng.normal(scale=NOISE_MM, size=(chin.sum(), 3))
    start = np.eye(4)
    start[:3, :3] = Rotation.from_rotvec(np.radians(3.0) * np.array([0.6, 0.8, 0.0])).as_matrix()
    start[:3, 3] = [1.5, -2.0, 1.7]
    start = start @ jaw
    surface = scan_surface(xyz, to_model, transform_points(start, region))[0]
    still = face & (y > 55)  # the forehead, sampled with the same noise
    forehead = v[still] + rng.normal(scale=NOISE_MM, size=(still.sum(), 3))
    still_surface = scan_surface(xyz, to_model, forehead)[0]
    plane, seen, _ = still_surface.residuals(forehead, still_surface.reach(forehead, 0.0))
    reference = robust_rms(plane[seen])
    res = region_motion(
        region, start, surface, IcpParams(kernel_k_mm=0.3, max_rmse_mm=1.5 * reference)
    )
    truth = transform_points(jaw, v[chin])
    err = np.linalg.norm(transform_points(res.transform, v[chin]) - truth, axis=1)
    before = np.linalg.norm(transform_points(start, v[chin]) - truth, axis=1)
    rms = lambda a: float(np.sqrt(np.mean(a**2)))  # noqa: E731
    print(
        f"\n[realdata] jaw (pout {pout_mm} mm): {chin.sum()} chin vertices, start {rms(before):.2f}"
        f" mm off -> {rms(err):.3f} mm; RMSE {res.residual_rmse:.3f} mm (limit "
        f"{res.rmse_limit:.3f}: 1.5 x the forehead's {reference:.3f}), constraint "
        f"{res.constraint:.3f}, covered {res.fitness:.2f}, {res.iterations} iterations"
    )
    assert rms(before) > 3.0
    if pout_mm == 0:
        assert res.ok, res.problems
        # measured 0.31 mm (0.10 without noise: the mesh's facets under smoothed normals)
        assert rms(err) < 0.5 and rms(err) < 0.1 * rms(before)
        assert res.constraint > MIN_CONSTRAINT
    else:
        assert not res.ok and "point-to-plane RMSE" in " ".join(res.problems)


def _colour_scan(
    head: Head,
    yaw_deg: float,
    pitch_deg: float,
    gain: float,
    zoom: float,
    size: tuple[int, int] = (WIDTH, HEIGHT),
):
    """A range image (camera frame, mm) and its colour image (the colour map under Lambert
    light from the camera, times ``gain``) of the head, with the camera's K, R (camera ->
    scanner) and centre; ``zoom`` times the range scan's focal length; ``size`` (width,
    height) px."""
    R_cw, centre = head.camera(yaw_deg=yaw_deg, pitch_deg=pitch_deg)
    f = zoom * head.focal_px()
    w, h = size
    K = np.array([[f, 0.0, 0.5 * (w - 1)], [0.0, f, 0.5 * (h - 1)], [0.0, 0.0, 1.0]])
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    d_cam = np.stack([(xs - K[0, 2]) / f, (ys - K[1, 2]) / f, np.ones_like(xs)], axis=-1)
    d_w = d_cam @ R_cw.T
    hit = head.cast(centre, d_w)
    valid = np.isfinite(hit["t"])
    xyz = np.where(valid[..., None], hit["t"][..., None] * d_cam, np.nan)
    uv = head.interpolate(head.uv, hit["face"], hit["bary"])
    col = (uv[..., 0] * head.texture.shape[1] - 0.5).astype(np.float32)
    row = ((1.0 - uv[..., 1]) * head.texture.shape[0] - 0.5).astype(np.float32)
    colour = cv2.remap(head.texture, col, row, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    normal = head.interpolate(head.normals, hit["face"], hit["bary"]) @ head.R_w.T
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    light = -d_w / np.linalg.norm(d_w, axis=-1, keepdims=True)
    shade = gain * (0.6 + 0.4 * np.clip(np.sum(normal * light, axis=-1), 0.0, 1.0))
    image = np.where(valid[..., None], shade[..., None] * colour.astype(np.float64), 0.0)
    return xyz, np.clip(np.rint(image), 0, 255).astype(np.uint8), K, R_cw, centre


def _project(points_w: np.ndarray, K: np.ndarray, R: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Pixels (n, 2) of scanner-frame points (n, 3), mm, in a pinhole camera (``K``, rotation
    ``R`` camera -> scanner, ``centre``)."""
    cam = (points_w - centre) @ R
    return cam[:, :2] / cam[:, 2:] @ K[:2, :2].T + K[:2, 2]


def test_upper_lip_prior_on_a_real_face(head):
    """The real face's upper lip (its own colours: a redness step of about 0.04 at the
    vermilion border, under stubble) seen from the front and from 8 degrees aside and 4 above
    in a 15% dimmer light. Seven lip columns are picked in the front view (the slit at the
    darkest row, the border where redness crosses halfway from skin to lip), their skin points
    projected into the other view are the truth. A flow that left the slit 3 px and the body
    1.5 px short of it: held to the neutral's length, the prior brings the slit to a median
    0.13 px and the body to 0.20 px; a right flow is kept (within 0.16 px: the border is held
    to 0.1 mm); by default (a strain of 10% allowed, about 1.1 px at the slit here) every slit
    vertex is brought to within 1.5 px."""
    from scan2morph.refine.lip import LipImages, LipParams, lip_prior, redness
    from scan2morph.template.regions import Lip
    from scan2morph.template.sample import sample_range

    xyz0, c0, K, R0, C0 = _colour_scan(head, 0.0, 0.0, 1.0, 2.0)
    xyz1, c1, _, R1, C1 = _colour_scan(head, 8.0, 4.0, 0.85, 2.0)
    nose = (head.nose @ head.R_w.T + head.t_w - C0) @ R0
    nose_px = K[:2, :2] @ (nose[:2] / nose[2]) + K[:2, 2]
    red, grey = redness(c0), c0.astype(np.float64).mean(axis=2)
    columns = np.rint(nose_px[0]).astype(int) + np.arange(-24, 25, 8)
    top = int(np.rint(nose_px[1])) + 72  # the mouth's rows, 30-45 mm under the nose tip
    inner, border = [], []
    for x in columns:
        slit = top + int(np.argmin(grey[top : top + 25, x]))
        skin, lip_red = red[slit - 26 : slit - 20, x].mean(), red[slit - 6 : slit - 2, x].mean()
        up = red[slit - 20 : slit, x] > 0.5 * (skin + lip_red)
        inner.append(slit - 3)
        border.append(slit - 20 + int(np.flatnonzero(up)[0]))
    inner, border = np.asarray(inner, float), np.asarray(border, float)
    rows = [border - 5, border, 0.5 * (inner + border), inner]  # skin, border, body, slit
    n = len(columns)
    points = np.concatenate([np.c_[columns, r] for r in rows])
    ids = np.arange(4 * n).reshape(4, n)
    i = (np.arange(n - 1)[None, :] + n * np.arange(3)[:, None]).ravel()
    faces = np.concatenate([np.c_[i, i + 1, i + n + 1], np.c_[i, i + n + 1, i + n]])
    region = Lip(ids[3], ids[1], ids[2])
    template = np.c_[np.tile(np.arange(n), 4), np.repeat(np.arange(4), n)] / 10.0
    skin_points, ok = sample_range(xyz0, points, "front", 1.0, None)
    assert ok.all()
    true = _project(C0 + skin_points @ R0.T, K, R1, C1)
    up = true[ids[1]] - true[ids[3]]
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    flow = true.copy()
    flow[ids[3]] += 3.0 * up
    flow[ids[2]] += 1.5 * up

    def run(take_points, params):
        images = LipImages(c0, xyz0, c1, xyz1)
        prior = lip_prior(
            region, template, points, take_points, images, faces, params, source="real"
        )
        placed = np.where(np.isfinite(prior.points), prior.points, take_points)
        return prior, np.linalg.norm(placed - true, axis=1)

    held, err = run(flow, LipParams(stretch=0.0))
    default, err_default = run(flow, LipParams())
    kept, err_kept = run(true, LipParams())
    slit, body = np.median(err[ids[3]]), np.median(err[ids[2]])
    print(
        f"\n[realdata] upper lip: redness step {held.contrast:.3f}, {held.measured}/"
        f"{held.vertices} placed; slit 3.0 -> {slit:.2f} px, body 1.5 -> {body:.2f} px (median; "
        f"10% stretch: slit {np.median(err_default[ids[3]]):.2f}); a right flow moved "
        f"{np.median(err_kept):.2f} px (median), {err_kept.max():.2f} px (max)"
    )
    assert held.used and held.measured == held.vertices and 0.02 < held.contrast < 0.1
    assert slit < 0.4 and body < 0.4  # measured 0.13 and 0.20
    assert default.used and (err_default[ids[3]] < 1.5).all()  # measured 0.92-1.32
    assert kept.used and err_kept.max() < 0.25  # measured 0.16


# --------------------------------------------------------------------------------------------
# the refinement's image correlation on the real skin's texture


@dataclass
class SkinScene:
    """The real face in a front view and smiling in another view, with the skin's truth.

    ``grid`` (n, 2) px are the template's vertices (a 3 px grid over the front view's face) and
    ``triangles`` (m, 3) its mesh; ``images`` the two grey images (1 grey level of noise);
    ``true`` (n, 2) px where each grid point's skin point went in the take's image; ``seen``
    (n,) the skin points the take's camera sees (a ray cast to each: not hidden behind the
    face); ``inner`` (n,) those 12 px or more inside the grid's edge (skin on every side of the
    correlation)."""

    grid: np.ndarray
    triangles: np.ndarray
    images: tuple[np.ndarray, np.ndarray]
    true: np.ndarray
    seen: np.ndarray
    inner: np.ndarray

    def fit(self, seed: int, spacing_px: float = 45.0, noise_px: float = 0.5):
        """The clicked grid points (k,) (seen, at least ``spacing_px`` apart, in a seeded
        random order) and a thin-plate spline through their true take pixels plus ``noise_px``
        of Gaussian noise: the template fit, a map of template points (n, 2) to pixels."""
        from scipy.interpolate import RBFInterpolator

        rng = np.random.default_rng(seed)
        clicks: list[int] = []
        for i in rng.permutation(len(self.grid)):
            near = np.linalg.norm(self.grid[clicks] - self.grid[i], axis=1) if clicks else [np.inf]
            if self.seen[i] and np.min(near) > spacing_px:
                clicks.append(i)
        clicked = self.true[clicks] + rng.normal(scale=noise_px, size=(len(clicks), 2))
        return np.asarray(clicks), RBFInterpolator(
            self.grid[clicks], clicked, kernel="thin_plate_spline"
        )


def skin_scene(head: Head) -> SkinScene:
    """The real face smiling (``_smile``: cheeks 5 mm up and out, mouth corners 6 mm), seen 4
    degrees aside and 2 above in a 15% dimmer light, against its front view (:class:`SkinScene`;
    seeded, so the same on every call)."""

    from scipy.spatial import Delaunay

    from scan2morph.refine import grey

    x, y = head.vertices[:, 0] - head.nose[0], head.vertices[:, 1] - head.nose[1]
    take = _moved(head, head.vertices + smile_displacement(x, y))
    smiled_w = take.vertices_w
    xyz0, c0, K, R0, C0 = _colour_scan(head, 0.0, 0.0, 1.0, 1.0)
    _, c1, _, R1, C1 = _colour_scan(take, 4.0, 2.0, 0.85, 1.0)
    rng = np.random.default_rng(SEED + 7)
    images = tuple(g + rng.normal(scale=1.0, size=g.shape) for g in (grey(c0), grey(c1)))

    rel = head.to_model(xyz0 @ R0.T + C0) - head.nose
    face = (
        np.isfinite(xyz0[..., 2])
        & head.is_face(rel + head.nose)
        & (np.abs(rel[..., 0]) < 55.0)
        & (rel[..., 1] > -75.0)
        & (rel[..., 1] < 45.0)
    )
    ys, xs = np.nonzero(face)
    gx, gy = np.meshgrid(np.arange(xs.min(), xs.max() + 1, 3), np.arange(ys.min(), ys.max() + 1, 3))
    grid = np.c_[gx.ravel(), gy.ravel()]
    grid = grid[face[grid[:, 1], grid[:, 0]]]
    triangles = Delaunay(grid).simplices
    sides = [
        np.linalg.norm(grid[triangles[:, a]] - grid[triangles[:, b]], axis=1)
        for a, b in ((0, 1), (1, 2), (2, 0))
    ]
    triangles = triangles[np.max(sides, axis=0) < 4.5]  # the grid's cells, not its hull

    # each grid point's skin point (its ray in the front view), smiled, in the take's view
    rays = np.c_[(grid - K[:2, 2]) / K[0, 0], np.ones(len(grid))] @ R0.T
    hit = head.cast(C0, rays)
    assert (hit["face"] >= 0).all()
    moved = head.interpolate(smiled_w, hit["face"], hit["bary"])
    back = take.cast(C1, moved - C1)["t"]  # 1 where the skin point is the first hit
    seen = np.abs(back - 1.0) * np.linalg.norm(moved - C1, axis=1) < 0.5
    depth = ndimage.distance_transform_edt(face)[grid[:, 1], grid[:, 0]]
    return SkinScene(
        grid.astype(np.float64), triangles, images, _project(moved, K, R1, C1), seen,
        seen & (depth >= 12),
    )  # fmt: skip


def skin_errors(scene: SkinScene, seed: int, params) -> dict[str, float]:
    """The fit's and the refinement's error on the scene's interior for one seeded draw of the
    clicks: RMS, median and 90th percentile, px, and the refinement's confident share."""
    from scan2morph.refine import refine_points

    clicks, spline = scene.fit(seed)
    refined, report = refine_points(
        scene.grid, scene.triangles, lambda p: np.asarray(p), spline, *scene.images, clicks, params
    )
    out = {"clicks": float(len(clicks)), "confident_share": report["confident_share"]}
    for name, p in (("fit", spline(scene.grid)), ("refined", refined)):
        e = np.linalg.norm(p - scene.true, axis=1)[scene.inner]
        out |= {
            f"{name}_rms": float(np.sqrt(np.mean(e**2))),
            f"{name}_median": float(np.median(e)),
            f"{name}_p90": float(np.percentile(e, 90)),
        }
    return out


def test_refinement_follows_real_skin(head):
    """The real face smiles and is seen from another pose in a dimmer light
    (:func:`skin_scene`); the template is a 3 px grid over the face in the front view and the
    fit a thin-plate spline through 11 clicks (0.5 px of noise) at least 45 px apart. Each grid
    point's skin point, carried by the smile and projected into the take, is the truth. With
    the config's refinement parameters the interior (12 px in from the grid's edge, where the
    flow sees skin on every side) comes from the fit's 1.68 px RMS to 0.24 px, a median of
    0.12 px. With the flow searched at half resolution (``refine.flow_level`` 1, before
    commit a9e65cd) it was 0.79 px, median 0.24; with the rounds, high-pass and membrane before
    commit 889e39b as well (2 rounds, a 4 px high-pass and membrane) 0.84 px, median 0.32. This
    is the parameters' check
    on real skin: the synthetic albedo is not the measure of them
    (``benchmarks/bench_refine_skin.py`` compares parameters over many draws of the clicks)."""

    from scan2morph.stages import refine as refine_stage

    config = repo_config()
    params = refine_stage.Params.from_config(config).flow
    scene = skin_scene(head)
    e = skin_errors(scene, SEED + 7, params)
    print(
        f"\n[realdata] refinement on real skin: {e['clicks']:.0f} clicks, true motion "
        f"{np.median(np.linalg.norm(scene.true - scene.grid, axis=1)):.1f} px (median); interior "
        f"{scene.inner.sum()} points: fit {e['fit_rms']:.2f} px RMS -> refined "
        f"{e['refined_rms']:.2f} px RMS, median {e['refined_median']:.2f} px; confident share "
        f"{e['confident_share']:.2f}"
    )
    assert scene.seen.mean() > 0.98 and e["fit_rms"] > 1.0
    assert e["refined_rms"] < 0.2 * e["fit_rms"] and e["refined_median"] < 0.16


def test_a_detection_far_off_on_the_real_head_is_flagged_doubtful():
    """The landmark detector (trained on synthetic heads only) on the real head's frontal colour
    render, against our hand annotation (tests/support/lps_landmarks.py): a detection off by
    more than 3 px (median) must say so through its confidence, so that the landmarks stage
    flags it doubtful and the report warns (measured: 8.5 px off, median confidence 0.06
    against about 0.7 on the held-out synthetic takes)."""
    from scan2morph.landmarks import detect
    from scan2morph.stages.landmarks import DETECTED, Landmarks
    from tests.support.lps_landmarks import load_real_head, real_takes

    (take,) = real_takes(load_real_head(), [(0, 0)])
    found = detect(take.color, take.xyz, "lps/front")
    error = float(np.median(np.linalg.norm(found.points - take.truth, axis=1)))
    landmarks = Landmarks(found.points, DETECTED, found.confidence, found.detector, found.version)
    doubt = landmarks.doubtful(0.5)
    print(f"\n[realdata] detector: {error:.1f} px off, median confidence "
          f"{np.median(found.confidence):.2f}")  # fmt: skip
    assert error <= 3.0 or doubt.startswith("the detected landmarks are doubtful")


# --------------------------------------------------------------------------------------------
# the template fit's forehead rim on a real brow raise


def _brow_raise(x: np.ndarray, y: np.ndarray, brow_y: float) -> np.ndarray:
    """A frontalis raise (V, 3) in the model frame, mm, at face coordinates relative to the nose
    tip (x right, y up; ``brow_y`` the brows' height): the brows 6 mm up at the midline and 4 mm
    at their tails, the forehead above following and falling linearly to a third of that 45 mm
    above the brows, the upper lids half-way (nothing from 12 mm below the brows down), fading
    out beyond 60 mm to the side. Our own field, not the synthetic generator's."""
    u = y - brow_y
    amplitude = 6.0 - 2.0 * np.clip(np.abs(x) / 45.0, 0.0, 1.0)
    rise = np.clip((u + 12.0) / 12.0, 0.0, 1.0)
    fall = np.where(u > 0, np.clip(1.0 - (2.0 / 3.0) * u / 45.0, 1.0 / 3.0, 1.0), 1.0)
    side = np.clip((75.0 - np.abs(x)) / 15.0, 0.0, 1.0)
    return (amplitude * rise * fall * side)[:, None] * np.array([0.0, 1.0, 0.0])


def test_the_fits_forehead_rim_on_a_real_brow_raise(head):
    """The real face raises its brows (:func:`_brow_raise`) and is seen 3 degrees aside and 1
    above; the fiducials are our hand annotation moved with the skin. Above the brows the plain
    thin-plate spline extrapolates the brows' motion with its own gradient; with the rim placed
    from the neutral's (``template.rim_share``, :mod:`scan2morph.template.rim`) the fit's top
    tenth of the template's rows is nearer the skin's true motion, and the rest of the face is
    fitted as well or better. Measured, the fit's RMS error in the top tenth / the rest, mm: plain
    5.83 / 1.06, the default share 0.5 1.90 / 0.75 (0: 2.86 / 0.97, 0.25: 1.18 / 0.80, 0.75:
    3.82 / 0.85), while the top tenth moves 3.87 mm RMS."""

    from scan2morph.stages import fit as fit_stage
    from scan2morph.template import build_template, fit_take, subdivide_template
    from scan2morph.template.rim import Rim
    from tests.support.lps_landmarks import LANDMARKS_MM

    config = repo_config()
    params = fit_stage.Params.from_config(config)
    brow_y = float(np.mean(LANDMARKS_MM[17:27, 1])) - head.nose[1]

    def field(model):
        rel = model - head.nose
        return _brow_raise(rel[:, 0], rel[:, 1], brow_y)

    take = _moved(head, head.vertices + field(head.vertices))
    xyz0, _, K, R0, C0 = _colour_scan(head, 0.0, 0.0, 1.0, 1.0)
    xyz1, _, _, R1, C1 = _colour_scan(take, 3.0, 1.0, 1.0, 1.0)
    to_w = lambda model: model @ head.R_w.T + head.t_w  # noqa: E731
    clicks0 = _project(to_w(LANDMARKS_MM), K, R0, C0)
    clicks1 = _project(to_w(LANDMARKS_MM + field(LANDMARKS_MM)), K, R1, C1)
    template = build_template()
    fine = subdivide_template(template, params.rules.levels)
    neutral = fit_take(template, clicks0, xyz0, rules=params.rules, source="real/neutral")
    # each neutral vertex's skin point, raised, in the take's camera frame
    model = head.to_model(neutral["vertices"] @ R0.T + C0)
    truth = (to_w(model + field(model)) - C1) @ R1
    top = fine.vertices[:, 1] <= np.quantile(fine.vertices[:, 1], 0.1)
    errors = {}
    for name, rim in (("plain", None), ("rim", Rim(clicks0, "closed", params.rim_share))):
        fit = fit_take(template, clicks1, xyz1, rules=params.rules, source="real/raise", rim=rim)
        e = np.linalg.norm(fit["vertices"] - truth, axis=1)
        ok = np.isfinite(e)
        errors[name] = [float(np.sqrt(np.mean(e[ok & m] ** 2))) for m in (top, ~top)]
    true_top = np.linalg.norm(field(model), axis=1)[top & np.isfinite(model).all(axis=1)]
    print(
        f"\n[realdata] brow raise, fit error RMS (top tenth of the rows / the rest), mm: plain "
        f"{errors['plain'][0]:.2f} / {errors['plain'][1]:.2f}, rim {errors['rim'][0]:.2f} / "
        f"{errors['rim'][1]:.2f}; the top tenth moves {np.sqrt(np.mean(true_top**2)):.2f} mm RMS"
    )
    assert errors["rim"][0] < 0.7 * errors["plain"][0]
    assert errors["rim"][1] < 1.05 * errors["plain"][1]
