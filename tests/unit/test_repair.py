"""Tests of scan2morph.scan.repair: spike removal and Williams hole filling.

Ground truth is an analytic sphere seen by a pinhole camera and moved into a tilted scanner
frame (so no coordinate is "the depth"); oracles are a per-pixel ``numpy.nanmedian`` loop,
a full-image ``scipy.ndimage.correlate`` implementation of Williams' steps, and OpenCV's
``cv2.inpaint`` (Telea and Navier-Stokes). ``sphere_range_image`` and ``punch_holes`` are also
used by ``benchmarks/bench_repair.py``.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import ndimage
from scipy.spatial.transform import Rotation

from scan2morph.errors import InputError
from scan2morph.scan import DEFAULT_REPAIR, fill_holes, remove_spikes, repair_range

#: Tilted scanner frame of the synthetic scenes: rotation vector (rad) and translation (mm).
FRAME_ROTVEC = (0.4, -0.7, 1.1)
FRAME_SHIFT_MM = (12.0, -30.0, 55.0)


def sphere_range_image(
    h: int,
    w: int,
    *,
    focal_px: float = 600.0,
    dist_mm: float = 600.0,
    radius_mm: float = 90.0,
    cap_deg: float | None = None,
    plane_mm: float | None = None,
    noise_mm: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """Range image (H, W, 3) mm of a sphere seen by a pinhole camera, in a tilted frame.

    The sphere (``radius_mm``, centre ``dist_mm`` along the optical axis) is kept where its
    normal is within ``cap_deg`` of the view axis (a face-like cap); ``plane_mm`` puts a valid
    background plane that far behind the centre, otherwise the background is NaN. Gaussian
    noise of ``noise_mm`` is added along the rays.
    """
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    ray = np.stack(
        [(u - (w - 1) / 2) / focal_px, (v - (h - 1) / 2) / focal_px, np.ones_like(u)], -1
    )
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    centre = np.array([0.0, 0.0, dist_mm])
    b = ray @ centre
    disc = b**2 - (centre @ centre - radius_mm**2)
    t = np.where(disc >= 0, b - np.sqrt(np.abs(disc)), np.nan)
    if cap_deg is not None:
        cos_normal = (dist_mm - ray[..., 2] * t) / radius_mm
        t = np.where(cos_normal >= np.cos(np.radians(cap_deg)), t, np.nan)
    if plane_mm is not None:
        t = np.where(np.isnan(t), (dist_mm + plane_mm) / ray[..., 2], t)
    t = t + noise_mm * rng.standard_normal(t.shape)
    rot = Rotation.from_rotvec(FRAME_ROTVEC).as_matrix()
    return (ray * t[..., None]) @ rot.T + np.asarray(FRAME_SHIFT_MM)


def punch_holes(
    valid: np.ndarray, areas: list[int], seed: int, *, spacing: int = 26
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Compact holes of exactly the given areas (px) at well separated valid places.

    Returns the union mask (H, W) and one mask per hole. Each hole is the ``area`` pixels
    nearest to a random sub-pixel centre (a digital disc), at least 4 px from any NaN.
    """
    rng = np.random.default_rng(seed)
    h, w = valid.shape
    margin = 4 + int(np.ceil(np.sqrt(max(areas) / np.pi)))
    inner = ndimage.binary_erosion(valid, np.ones((3, 3)), iterations=margin)
    cy, cx = np.mgrid[spacing // 2 : h : spacing, spacing // 2 : w : spacing]
    ok = inner[cy, cx]
    cy, cx = cy[ok], cx[ok]
    if cy.size < len(areas):
        raise ValueError("scene too small for the requested holes")
    pick = rng.choice(cy.size, len(areas), replace=False)
    v, u = np.mgrid[0:h, 0:w]
    union = np.zeros((h, w), bool)
    masks = []
    for area, k in zip(areas, pick, strict=True):
        d2 = (u - cx[k] - rng.uniform(-0.5, 0.5)) ** 2 + (v - cy[k] - rng.uniform(-0.5, 0.5)) ** 2
        m = np.zeros(h * w, bool)
        m[np.argsort(d2, axis=None, kind="stable")[:area]] = True
        masks.append(m.reshape(h, w))
        union |= masks[-1]
    return union, masks


def cv2_inpaint(xyz: np.ndarray, mask: np.ndarray, method: int, radius_px: float = 3) -> np.ndarray:
    """cv2.inpaint per coordinate on float32 (NaN set to 0 outside the holes)."""
    out = np.empty_like(xyz)
    m8 = mask.astype(np.uint8)
    for i in range(3):
        out[..., i] = cv2.inpaint(
            np.nan_to_num(xyz[..., i]).astype(np.float32), m8, radius_px, method
        )
    return out


def rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS of 3D distances, mm."""
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


# ---------------------------------------------------------------------------------------------
# fill_holes


SIZES = [1, 4, 16, 64, 200]


@pytest.fixture(scope="module")
def smooth_scene() -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """A sphere filling the whole 150 x 180 image, no noise, 3 holes of each size."""
    truth = sphere_range_image(150, 180, radius_mm=200.0)
    assert np.isfinite(truth).all()
    union, masks = punch_holes(np.ones(truth.shape[:2], bool), SIZES * 3, seed=1)
    return truth, union, masks


def test_fill_small_holes_matches_analytic_surface(smooth_scene):
    truth, union, masks = smooth_scene
    xyz = truth.copy()
    xyz[union] = np.nan
    out, rep = fill_holes(xyz, max_hole_px=400)
    assert rep["n_holes"] == rep["n_filled"] == len(masks)
    assert rep["filled_px"] == union.sum() == sum(SIZES) * 3
    assert rep["unfilled_holes"] == [] and rep["largest_unfilled_px"] == 0
    assert_array_equal(rep["filled"], union)
    assert_array_equal(out[~union], truth[~union])  # data untouched
    for size in SIZES:
        m = np.any([mk for mk in masks if mk.sum() == size], axis=0)
        err = rms(out[m], truth[m])
        print(f"\nfill_holes {size:4d} px holes: RMS {err:.5f} mm")
        assert err < 0.01
    assert rms(out[union], truth[union]) < 0.005


@pytest.mark.parametrize("degree", [0, 1, 2])
def test_fill_is_exact_for_polynomials_of_its_degree(degree):
    """Degree 0 is exact on constants, 1 on affine and 2 on quadratic pixel-coordinate maps."""
    rng = np.random.default_rng(7)
    v, u = np.mgrid[0:60, 0:70].astype(np.float64)
    terms = [np.ones_like(u), u, v, u * u, u * v, v * v][: [1, 3, 6][degree]]
    coef = (
        rng.normal(size=(len(terms), 3))
        * np.array([100.0, 0.7, 0.7, 0.01, 0.01, 0.01])[: len(terms), None]
    )
    truth = np.einsum("thw,tc->hwc", np.stack(terms), coef)
    union, _ = punch_holes(np.ones((60, 70), bool), [3, 30, 90], seed=degree, spacing=20)
    xyz = truth.copy()
    xyz[union] = np.nan
    out, rep = fill_holes(xyz, max_hole_px=100, trend_degree=degree)
    assert rep["n_filled"] == 3
    assert_allclose(out[union], truth[union], atol=1e-9)


def _williams_reference(xyz, gaps, kernel_px, threshold, max_iter):
    """Steps 0-4 of the paper on the full image with scipy.ndimage.correlate (oracle)."""
    valid = ~np.isnan(xyz[..., 0])
    surf = np.where(valid[..., None], xyz, 0.0)
    matte = valid.astype(np.float64)
    k1 = np.array([1.0])
    for _ in range(kernel_px - 1):
        k1 = np.convolve(k1, [1.0, 1.0])
    kern = np.outer(k1, k1) / k1.sum() ** 2
    todo = gaps.copy()
    for _ in range(max_iter):
        bm = ndimage.correlate(matte, kern, mode="constant")
        bs = np.stack(
            [ndimage.correlate(surf[..., i], kern, mode="constant") for i in range(3)], -1
        )
        upd = todo & (bm > threshold)
        surf[upd] = bs[upd] / bm[upd, None]
        matte[upd] = 1.0
        todo &= ~upd
        if not todo.any():
            break
    out = xyz.copy()
    out[gaps] = surf[gaps]
    return out


@pytest.mark.parametrize(("kernel_px", "threshold"), [(3, 0.2), (5, 0.1)])
def test_paper_filter_matches_full_image_reference(kernel_px, threshold):
    truth = sphere_range_image(70, 80, radius_mm=150.0, noise_mm=0.2, seed=2)
    union, _ = punch_holes(np.ones((70, 80), bool), [5, 40, 120], seed=3, spacing=22)
    xyz = truth.copy()
    xyz[union] = np.nan
    out, rep = fill_holes(
        xyz, max_hole_px=200, kernel_px=kernel_px, threshold=threshold, trend_degree=0
    )
    ref = _williams_reference(xyz, union, kernel_px, threshold, max_iter=100)
    assert rep["n_filled"] == 3
    assert_allclose(out, ref, rtol=0, atol=1e-9)


def test_large_holes_and_background_stay_nan():
    truth = sphere_range_image(120, 150, cap_deg=60.0)  # NaN background around a cap
    valid = np.isfinite(truth[..., 0])
    union, masks = punch_holes(valid, [30, 401, 900], seed=4, spacing=34)
    xyz = truth.copy()
    xyz[union] = np.nan
    out, rep = fill_holes(xyz, max_hole_px=400)
    assert rep["n_holes"] == 3 and rep["n_filled"] == 1
    assert rep["unfilled_holes"] == [900, 401] and rep["largest_unfilled_px"] == 900
    assert_array_equal(rep["filled"], masks[0])
    assert np.isnan(out[masks[1] | masks[2] | ~valid]).all()
    assert rms(out[masks[0]], truth[masks[0]]) < 0.01


def test_hole_the_filter_cannot_close_is_reported_unfilled():
    truth = sphere_range_image(40, 40, radius_mm=150.0)
    xyz = truth.copy()
    xyz[10:20, 10:20] = np.nan
    xyz[30, 30] = np.nan
    out, rep = fill_holes(xyz, max_hole_px=400, max_iter=2)  # 10 x 10 needs 5 passes
    assert rep["n_holes"] == 2 and rep["n_filled"] == 1
    assert rep["unfilled_holes"] == [100] and rep["n_iter"] == 2
    assert np.isnan(out[10:20, 10:20]).all() and rep["filled"].sum() == 1


def test_hole_across_a_depth_step_stays_or_falls_back_to_the_paper_filter():
    v, u = np.mgrid[0:40, 0:60].astype(np.float64)
    rot = Rotation.from_rotvec(FRAME_ROTVEC).as_matrix()
    depth = np.where(u >= 30, 530.0, 500.0)  # a 30 mm step between two fronto-parallel planes
    xyz = np.stack([0.5 * (u - 30), 0.5 * (v - 20), depth], -1) @ rot.T
    hole = np.zeros((40, 60), bool)
    hole[18:22, 28:32] = True
    xyz[hole] = np.nan
    # a hole larger than max_edge_hole_px whose rim spans the step stays a hole, with its area
    kept, rep_kept = fill_holes(xyz, max_edge_hole_px=15)
    assert rep_kept["n_trend_rejected"] == 1 and rep_kept["n_filled"] == 0
    assert rep_kept["unfilled_holes"] == [16] and not rep_kept["filled"].any()
    assert_allclose(kept, xyz, rtol=0, atol=0, equal_nan=True)
    # a smaller one (the default bound is 50 px) is filled by the paper's filter (no trend
    # terms), within the rim's range
    out, rep = fill_holes(xyz, max_edge_hole_px=16)
    paper, rep0 = fill_holes(xyz, trend_degree=0)
    assert rep["n_trend_rejected"] == 1 and rep0["n_trend_rejected"] == 0
    assert rep["n_filled"] == 1 and rep["unfilled_holes"] == []
    assert_allclose(out, paper, rtol=0, atol=1e-12, equal_nan=True)
    rim = ndimage.binary_dilation(hole, np.ones((3, 3))) & ~hole
    assert (out[hole] >= xyz[rim].min(0) - 1e-9).all() and (
        out[hole] <= xyz[rim].max(0) + 1e-9
    ).all()


def test_filler_beats_cv2_inpaint(smooth_scene):
    """Ours against cv2.inpaint (Telea, NS) on the same holes, with and without noise.

    Stated factors: the default (trend-corrected) filler is at least as good as the better cv2
    method; the paper's filter as is (trend_degree=0) within 4x of it.
    """
    truth, union, masks = smooth_scene
    noisy = sphere_range_image(150, 180, radius_mm=200.0, noise_mm=0.1, seed=5)
    for label, scan in (("noise 0", truth), ("noise 0.1 mm", noisy)):
        xyz = scan.copy()
        xyz[union] = np.nan
        ours = fill_holes(xyz, max_hole_px=400)[0]
        paper = fill_holes(xyz, max_hole_px=400, trend_degree=0)[0]
        telea = cv2_inpaint(xyz, union, cv2.INPAINT_TELEA)
        ns = cv2_inpaint(xyz, union, cv2.INPAINT_NS)
        e = {
            k: rms(a[union], truth[union])
            for k, a in [("ours", ours), ("paper", paper), ("telea", telea), ("ns", ns)]
        }
        print(
            f"\n{label}: RMS mm ours {e['ours']:.4f}  paper(deg 0) {e['paper']:.4f}  "
            f"cv2 Telea {e['telea']:.4f}  cv2 NS {e['ns']:.4f}"
        )
        best_cv2 = min(e["telea"], e["ns"])
        assert e["ours"] <= 1.0 * best_cv2
        assert e["paper"] <= 4.0 * best_cv2


# ---------------------------------------------------------------------------------------------
# remove_spikes


@pytest.fixture(scope="module")
def edge_scene() -> np.ndarray:
    """A 60-degree cap 85 mm in front of a valid plane, NaN corner, 0.1 mm noise."""
    xyz = sphere_range_image(180, 220, cap_deg=60.0, plane_mm=40.0, noise_mm=0.1, seed=6)
    xyz[:30, :40] = np.nan
    return xyz


def _add_spikes(xyz, n, lo_mm, hi_mm, seed):
    rng = np.random.default_rng(seed)
    valid = np.isfinite(xyz[..., 0])
    idx = rng.choice(np.flatnonzero(valid), n, replace=False)
    direction = rng.standard_normal((n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    out = xyz.copy().reshape(-1, 3)
    out[idx] += direction * rng.uniform(lo_mm, hi_mm, (n, 1))
    truth = np.zeros(valid.shape, bool)
    truth.ravel()[idx] = True
    return out.reshape(xyz.shape), truth


def test_spikes_found_with_few_false_positives_at_depth_edges(edge_scene):
    thr = 5.0
    valid = np.isfinite(edge_scene[..., 0])
    xyz, truth = _add_spikes(edge_scene, 400, 3 * thr, 60.0, seed=8)
    clean, spikes = remove_spikes(xyz, thr)
    recall = (spikes & truth).sum() / truth.sum()
    fp_rate = (spikes & ~truth).sum() / valid.sum()
    print(f"\nremove_spikes: recall {recall:.4f}, false positives {fp_rate * 100:.4f}% of valid")
    assert recall == 1.0
    assert fp_rate < 1e-3
    assert_array_equal(np.isnan(clean[..., 0]), ~valid | spikes)
    assert_array_equal(clean[~spikes], xyz[~spikes])


def test_depth_edges_without_support_test_would_be_flagged(edge_scene):
    """Why min_support exists: the median test alone flags the cap's rim."""
    _, spikes = remove_spikes(edge_scene, 5.0)
    _, median_only = remove_spikes(edge_scene, 5.0, min_support=24)
    assert spikes.sum() == 0
    assert median_only.sum() > 1e-3 * np.isfinite(edge_scene[..., 0]).sum()


@pytest.mark.parametrize(
    ("noise_mm", "thr", "window", "min_support"),
    [(0.0, 4.0, 5, 3), (1.0, 1.5, 5, 24), (1.0, 1.5, 3, 8), (0.5, 2.0, 7, 10)],
)
def test_spike_test_matches_per_pixel_nanmedian(noise_mm, thr, window, min_support):
    """Against a per-pixel numpy.median loop; noisy cases put many pixels near the threshold."""
    scene = sphere_range_image(24, 30, cap_deg=60.0, radius_mm=20.0, noise_mm=noise_mm, seed=4)
    xyz, _ = _add_spikes(scene, 30, 1, 30, 9)
    xyz[5:8, 5:8] = np.nan
    _, spikes = remove_spikes(xyz, thr, window, min_support=min_support)
    h, w, r = 24, 30, window // 2
    pad = np.pad(xyz, ((r, r), (r, r), (0, 0)), constant_values=np.nan)
    expect = np.zeros((h, w), bool)
    for y in range(h):
        for x in range(w):
            if np.isnan(xyz[y, x, 0]):
                continue
            nb = pad[y : y + window, x : x + window].reshape(-1, 3)
            nb = np.delete(nb, window * window // 2, axis=0)
            nb = nb[~np.isnan(nb[:, 0])]
            if len(nb) < max(3, (window * window - 1) // 4):
                continue
            far = np.linalg.norm(xyz[y, x] - np.median(nb, axis=0)) > thr
            support = np.sum(np.linalg.norm(nb - xyz[y, x], axis=1) <= thr)
            expect[y, x] = far and support < min_support
    assert 5 < expect.sum() < 0.9 * np.isfinite(xyz[..., 0]).sum()
    assert_array_equal(spikes, expect)


def test_point_with_too_few_neighbours_is_left_alone():
    xyz = np.full((20, 20, 3), np.nan)
    xyz[5:15, 5:15] = [1.0, 2.0, 3.0]
    xyz[2, 2] = [100.0, 0.0, 0.0]  # lone point in the background: no neighbours
    xyz[10, 10] = [1.0, 2.0, 30.0]  # spike inside the patch
    _, spikes = remove_spikes(xyz, 5.0)
    assert_array_equal(np.argwhere(spikes), [[10, 10]])


# ---------------------------------------------------------------------------------------------
# repair_range


def test_repair_range_removes_spikes_then_fills_them():
    truth = sphere_range_image(100, 120, radius_mm=200.0, noise_mm=0.0)
    xyz, spiked = _add_spikes(truth, 60, 20.0, 50.0, seed=10)
    hole = np.zeros(truth.shape[:2], bool)
    hole[40:45, 50:56] = True
    xyz[hole] = np.nan
    out, rep = repair_range(xyz, {"max_hole_px": 50})
    assert rep["n_spikes"] == 60
    assert_array_equal(rep["spikes"], spiked)
    # a removed spike on the image border joins the background: it stays NaN
    on_border = np.zeros_like(hole)
    on_border[[0, -1], :] = on_border[:, [0, -1]] = True
    inner = spiked & ~on_border
    assert (spiked & on_border).any()
    assert_array_equal(rep["filled"], inner | hole)
    assert_array_equal(np.isnan(out[..., 0]), spiked & on_border)
    err = rms(out[inner | hole], truth[inner | hole])
    print(f"\nrepair_range: RMS of refilled spikes and hole {err:.5f} mm")
    assert err < 0.01
    # a hole above max_hole_px is reported, the spikes still filled
    out2, rep2 = repair_range(xyz, {"max_hole_px": 10})
    assert rep2["unfilled_holes"] == [30] and np.isnan(out2[hole]).all()
    assert np.isfinite(out2[inner]).all()


def test_default_params_are_the_documented_ones():
    assert DEFAULT_REPAIR == {
        "spike_threshold_mm": 5.0,
        "spike_window": 5,
        "max_hole_px": 400,
        "fill_kernel_px": 3,
        "fill_threshold": 0.2,
        "fill_max_iter": 100,
        "max_edge_hole_px": 50,
    }


# ---------------------------------------------------------------------------------------------
# bad input


GOOD = np.zeros((8, 9, 3))


@pytest.mark.parametrize("func", [remove_spikes, fill_holes, repair_range])
@pytest.mark.parametrize(
    ("xyz", "match"),
    [
        (np.zeros((8, 9)), r"xyz: expected shape \(H, W, 3\)"),
        (np.zeros((8, 9, 4)), r"xyz: expected shape \(H, W, 3\)"),
        (np.zeros((2, 9, 3)), r"xyz: expected H, W >= 3"),
        (np.full((8, 9, 3), np.nan), r"xyz: no valid pixel \(all NaN\)"),
        (np.zeros((8, 9, 3), np.int32), r"xyz: expected a float array.*int32"),
        (np.zeros((8, 9, 3), bool), r"xyz: expected a float array.*bool"),
        (np.where(np.eye(9)[:8, :, None], np.inf, GOOD), r"xyz: expected finite values"),
    ],
)
def test_bad_xyz_raises(func, xyz, match):
    with pytest.raises(InputError, match="^s1/t2: " + match):
        func(xyz, source="s1/t2")


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"spike_treshold_mm": 5.0}, r"params: unknown key\(s\) \['spike_treshold_mm'\]"),
        ({"spike_threshold_mm": 0.0}, r"params.spike_threshold_mm: expected a finite number > 0"),
        ({"spike_threshold_mm": -1.0}, r"params.spike_threshold_mm: expected a finite number > 0"),
        ({"spike_threshold_mm": float("nan")}, r"params.spike_threshold_mm: expected a finite"),
        ({"spike_threshold_mm": "5"}, r"params.spike_threshold_mm: expected a number"),
        ({"spike_window": 4}, r"params.spike_window: expected an odd integer >= 3, got 4"),
        ({"spike_window": 0}, r"params.spike_window: expected an odd integer >= 3, got 0"),
        ({"spike_window": 5.0}, r"params.spike_window: expected an integer"),
        ({"max_hole_px": 0}, r"params.max_hole_px: expected an integer >= 1, got 0"),
        ({"max_hole_px": True}, r"params.max_hole_px: expected an integer, got True"),
        ({"fill_kernel_px": -3}, r"params.fill_kernel_px: expected an odd integer >= 3"),
        ({"fill_threshold": 0}, r"params.fill_threshold: expected a finite number in \(0, 1.0\)"),
        ({"fill_threshold": 1.0}, r"params.fill_threshold: expected a finite number in \(0, 1.0\)"),
        ({"max_edge_hole_px": -1}, r"params.max_edge_hole_px: expected an integer >= 0"),
        ({"fill_max_iter": -2}, r"params.fill_max_iter: expected an integer >= 1, got -2"),
    ],
)
def test_bad_params_raise(params, match):
    with pytest.raises(InputError, match="^repair: " + match):
        repair_range(GOOD, params)


def test_param_errors_name_the_config_section_not_the_take():
    with pytest.raises(InputError, match=r"^repair: params.max_hole_px: expected an integer >= 1"):
        repair_range(GOOD, {"max_hole_px": 0}, source="s1/t2")
    with pytest.raises(InputError, match=r"^repair: window: expected an odd integer >= 3"):
        remove_spikes(GOOD, window=2, source="s1/t2")


def test_params_not_a_dict_raises():
    with pytest.raises(InputError, match=r"^repair: params: expected a dict, got list"):
        repair_range(GOOD, [("max_hole_px", 3)])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: remove_spikes(GOOD, threshold_mm=-5.0), r"threshold_mm: expected a finite"),
        (lambda: remove_spikes(GOOD, window=6), r"window: expected an odd integer >= 3"),
        (lambda: remove_spikes(GOOD, min_support=0), r"min_support: expected an integer >= 1"),
        (lambda: fill_holes(GOOD, max_hole_px=-1), r"max_hole_px: expected an integer >= 1"),
        (lambda: fill_holes(GOOD, kernel_px=1), r"kernel_px: expected an odd integer >= 3"),
        (lambda: fill_holes(GOOD, threshold=1.5), r"threshold: expected a finite number in"),
        (lambda: fill_holes(GOOD, max_iter=0), r"max_iter: expected an integer >= 1"),
        (lambda: fill_holes(GOOD, trend_degree=3), r"trend_degree: expected 0, 1 or 2, got 3"),
    ],
)
def test_bad_function_arguments_raise(call, match):
    with pytest.raises(InputError, match="^repair: " + match):
        call()
