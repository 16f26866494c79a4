"""Figures of every stage, drawn from a synthetic subject store with known fields."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from matplotlib import colormaps
from PIL import Image
from scipy.spatial.transform import Rotation

from scan2morph.errors import InputError
from scan2morph.geometry import TexturedMesh
from scan2morph.render.charts import bars
from scan2morph.render.figures import (
    STAGE_FIGURES,
    figure_names,
    stage_figures,
    write_figures,
    write_stage_figures,
)
from scan2morph.render.fit_figures import fig_landmarks, fig_model
from scan2morph.render.modal_figures import (
    fig_expressions,
    fig_modes,
    fig_reconstruction,
    fig_statistics,
    fig_synthesis,
)
from scan2morph.render.morph_figures import blend_title, fig_eigen, fig_gradual, pca_alphas
from scan2morph.render.motion_figures import fig_alignment, fig_click_noise, fig_distance, fig_mask
from scan2morph.render.names import FIGURE_NAMES
from scan2morph.render.source import (
    StoreMapping,
    example_take,
    expression_takes,
    neutral_take,
    viseme_takes,
)
from scan2morph.render.views import (
    DPI,
    PANEL_PX,
    ColorScale,
    Panel,
    axes_off,
    face_view,
    figure_panels,
    figure_to_array,
    grid_layout,
    opaque_rgba,
    panel_figure,
    render_view,
    subplots,
)
from scan2morph.store import merge_parts, paths, write_part

SCALE_MM = 45.0  # template unit (half the outer-eye distance) in mm
DEPTH_MM = 1000.0
FOCAL_PX, WIDTH, HEIGHT = 1450.0, 640, 480
ICP_NAMES = (
    "eye_r_outer",
    "eye_r_inner",
    "eye_l_inner",
    "eye_l_outer",
    "nose_bridge",
    "forehead_centre",
)


# --------------------------------------------------------------------------------------------
# A synthetic store: a grid "face" with every dataset of schemas/store.layout.yaml
# --------------------------------------------------------------------------------------------
def grid_template(nx: int = 9, ny: int = 11):
    """A grid in template coordinates (x right, y down), faces counter-clockwise as seen."""
    x, y = np.meshgrid(np.linspace(-1.5, 1.5, nx), np.linspace(-1.3, 2.3, ny))
    xy = np.column_stack([x.ravel(), y.ravel()])
    i = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    faces = np.vstack([np.column_stack([a, c, b]), np.column_stack([b, c, d])])
    named = {
        "forehead_centre": (0.0, -1.1),
        "chin": (0.0, 2.3),
        "eye_r_outer": (-1.0, 0.0),
        "eye_r_inner": (-0.4, 0.0),
        "eye_l_inner": (0.4, 0.0),
        "eye_l_outer": (1.0, 0.0),
        "nose_bridge": (0.0, 0.1),
        "nose_tip": (0.0, 1.0),
    }
    ibug = {37: (-1.0, 0.0), 46: (1.0, 0.0), 49: (-0.5, 1.5), 55: (0.5, 1.5), 62: (0.0, 1.4)}
    nearest = lambda p: int(np.argmin(np.linalg.norm(xy - np.asarray(p), axis=1)))  # noqa: E731
    names = [f"ibug{n:02d}" for n in ibug] + list(named)
    indices = [nearest(p) for p in ibug.values()] + [nearest(p) for p in named.values()]
    return xy, faces, names, np.asarray(indices), None


def _height(xy):
    x, y = xy[:, 0], xy[:, 1]
    dome = 70.0 * np.sqrt(np.clip(1 - (x / 1.8) ** 2 - ((y - 0.5) / 2.5) ** 2, 0, None))
    nose = 22.0 * np.exp(-((x / 0.28) ** 2) - ((y - 0.55) / 0.55) ** 2)
    return dome + nose


def _deformation(xy, kind):
    """Displacement (V, 3) in the camera frame (x right, y down, z away), mm."""
    x, y = xy[:, 0], xy[:, 1]
    d = np.zeros((len(xy), 3))
    if kind == "car":  # jaw drop
        d[:, 1] = 14.0 * np.clip((y - 1.2) / 1.1, 0, 1)
    elif kind == "too":  # pucker
        g = np.exp(-((x / 0.45) ** 2) - ((y - 1.5) / 0.35) ** 2)
        d[:, 2] = -7.0 * g
        d[:, 0] = -3.0 * x * g
    elif kind.startswith("smile"):
        g = np.exp(-(((np.abs(x) - 0.55) / 0.3) ** 2) - ((y - 1.45) / 0.3) ** 2)
        d[:, 0], d[:, 1] = 4.0 * np.sign(x) * g, -3.0 * g * (1.1 if kind.endswith("2") else 1.0)
    elif kind == "sad1":
        g = np.exp(-(((np.abs(x) - 0.55) / 0.3) ** 2) - ((y - 1.5) / 0.3) ** 2)
        d[:, 1] = 4.0 * g
    return d


def synthetic_store(template=None, seed: int = 0) -> dict[str, np.ndarray]:
    """Every dataset of the layout for a subject: neutral, visemes car and too, expressions smile1,
    smile2 (label smile) and sad1 (label sad), all in an arbitrarily rotated frame."""
    rng = np.random.default_rng(seed)
    xy, faces, names, indices, ibug_xy = template if template is not None else grid_template()
    frame = Rotation.random(random_state=rng).as_matrix()  # the neutral frame, arbitrary
    store: dict[str, np.ndarray] = {
        paths.template("faces"): faces.astype(np.int64),
        paths.template("vertices2d"): xy.astype(float),
        paths.template("fiducials/names"): np.asarray(names, dtype=object),
        paths.template("fiducials/indices"): np.asarray(indices, dtype=np.int64),
    }
    aligned = {}
    for n, take in enumerate(["neutral", "car", "too", "smile1", "smile2", "sad1"]):
        aligned[take] = _take_datasets(store, take, n, xy, ibug_xy, frame, rng)
    neutral = aligned["neutral"]
    suppressed = xy[:, 1] < 0.3
    store |= {
        paths.neutral("vertices"): neutral,
        paths.neutral("filled"): np.zeros(len(xy), dtype=bool),
        paths.mask("suppressed"): suppressed,
        paths.mask("seeds"): np.flatnonzero(np.abs(xy[:, 1] + 0.4) < 0.2),
    }
    models = _viseme_datasets(store, aligned, suppressed)
    _pca_datasets(store, neutral, models)
    _modal_datasets(store, xy, faces, frame, aligned)
    return store


def _take_datasets(store, take: str, n: int, xy, ibug_xy, frame, rng) -> np.ndarray:
    """A take's image, landmarks, fit and alignment (the n-th take, posed at random but the
    neutral); returns its aligned vertices."""
    v = len(xy)
    camera = np.column_stack([SCALE_MM * xy, DEPTH_MM - _height(xy)])
    deformed = camera + _deformation(xy, take)
    pose = np.eye(4)
    if n:
        pose[:3, :3] = Rotation.from_rotvec(rng.normal(0, np.radians(3), 3)).as_matrix()
        pose[:3, 3] = rng.normal(0, 15, 3)
    scan_cam = deformed @ pose[:3, :3].T + pose[:3, 3]  # the take's camera frame
    u = FOCAL_PX * scan_cam[:, 0] / scan_cam[:, 2] + WIDTH / 2
    w = FOCAL_PX * scan_cam[:, 1] / scan_cam[:, 2] + HEIGHT / 2
    valid = np.ones(v, dtype=bool)
    if n:
        valid[rng.choice(v, 3, replace=False)] = False
    scan = scan_cam @ frame.T  # the take's scanner frame: the same arbitrary rotation
    scan[~valid] = np.nan
    # scanner -> neutral frame: undo the take's pose in camera coordinates
    to_neutral = np.eye(4)
    to_neutral[:3, :3] = frame @ pose[:3, :3].T @ frame.T
    to_neutral[:3, 3] = -to_neutral[:3, :3] @ (frame @ pose[:3, 3])
    aligned = scan @ to_neutral[:3, :3].T + to_neutral[:3, 3]
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH]
    color = np.stack(
        [
            180 + 40 * np.sin(xx / 23.0),
            140 + 30 * np.cos(yy / 17.0),
            120 + 20 * np.sin((xx + yy) / 31.0),
        ],
        axis=-1,
    ).astype(np.uint8)
    if ibug_xy is None:
        marks = rng.uniform([u.min(), w.min()], [u.max(), w.max()], (68, 2))
    else:
        marks = np.asarray(ibug_xy) * SCALE_MM * FOCAL_PX / DEPTH_MM + [WIDTH / 2, HEIGHT / 2]
    store |= {
        paths.range_image(take, "color"): color,
        paths.landmarks(take): marks,
        paths.mesh(take, "vertices"): scan,
        paths.mesh(take, "uv"): np.column_stack([(u + 0.5) / WIDTH, (w + 0.5) / HEIGHT]),
        paths.mesh(take, "valid"): valid,
        paths.mesh(take, "points2d"): np.column_stack([u, w]),
        paths.align(take, "transform"): to_neutral,
        paths.align(take, "vertices"): aligned,
    }
    return aligned


def _viseme_datasets(store, aligned, suppressed) -> dict[str, np.ndarray]:
    """The visemes' motion, models and click-noise error bar; returns the models."""
    neutral = aligned["neutral"]
    models = {}
    for take in ("car", "too"):
        raw = aligned[take] - neutral
        motion = np.where(suppressed[:, None], 0.0, np.nan_to_num(raw))
        models[take] = neutral + motion
        store |= {
            paths.viseme(take, "motion_raw"): raw,
            paths.viseme(take, "motion"): motion,
            paths.viseme(take, "model"): models[take],
        }
    # click-noise error bar: 1 mm on car, 0.5 mm on too, nothing under the mask
    noise = {t: np.where(suppressed, 0.0, a) for t, a in (("car", 1.0), ("too", 0.5))}
    store |= {paths.viseme(t, "noise_rms_mm"): n for t, n in noise.items()}
    store |= {
        paths.motion_noise("takes"): np.asarray(["car", "too"], dtype=object),
        paths.motion_noise("relative"): np.array([0.1, 0.2]),
        paths.motion_noise("rms_error_mm"): np.array([1.0, 0.5]),
    }
    return models


def _pca_datasets(store, neutral: np.ndarray, models: dict) -> None:
    """PCA over neutral + viseme models (the paper's convention: eigenvalue = sum of coef^2),
    blend shapes and a PCA blend."""
    v = len(neutral)
    shapes = np.stack([neutral, *models.values()])
    mean = shapes.mean(axis=0)
    centred = (shapes - mean).reshape(len(shapes), -1)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    k = len(shapes) - 1
    comps, eig = vt[:k], s[:k] ** 2
    store |= {
        paths.pca("mean"): mean,
        paths.pca("components"): comps.reshape(k, v, 3),
        paths.pca("eigenvalues"): eig,
        paths.pca("cr"): eig / eig.sum(),
        paths.pca("ccr"): np.cumsum(eig) / eig.sum(),
        paths.pca("coefficients"): centred @ comps.T,
        paths.pca("takes"): np.asarray(["neutral", "car", "too"], dtype=object),
        # the default convention: sigma = sample std of the coefficients
        paths.pca("sigma"): np.std(centred @ comps.T, axis=0, ddof=1),
        paths.pca("sigma_convention"): "sample",
    }
    sigma = store[paths.pca("sigma")]
    for label in ("car", "too"):
        for pct in (30, 60, 90):
            store[paths.blend(f"{label}_{pct}")] = neutral + pct / 100 * (models[label] - neutral)
    store[paths.blend("too50_car20")] = (
        neutral + 0.5 * (models["too"] - neutral) + 0.2 * (models["car"] - neutral)
    )
    store[paths.pca_blend("pca_blend1")] = mean + (
        0.5 * sigma[0] * comps[0] + 1.0 * sigma[1] * comps[1]
    ).reshape(v, 3)


def _modal_datasets(store, xy, faces, frame, aligned) -> None:
    """A modal basis of smooth normal-direction patterns on the face (frequencies ascending),
    the expressions' coordinates, reconstructions and per-label statistics."""
    v, neutral = len(xy), aligned["neutral"]
    normal = frame @ np.array([0.0, 0.0, -1.0])
    n_modes = 8
    modes = np.stack(
        [
            np.outer(
                np.sin((j % 3 + 1) * np.pi * (xy[:, 0] + 1.5) / 3.0)
                * np.sin((j // 3 + 1) * np.pi * (xy[:, 1] + 1.3) / 3.6),
                normal,
            )
            for j in range(n_modes)
        ]
    )
    ks = np.array([1, 2, 5, 8])
    store |= {
        paths.modal("frequencies_hz"): 40.0 * np.arange(1, n_modes + 1),
        paths.modal("modes"): modes,
        paths.modal("dof_modes"): np.concatenate([modes, np.zeros_like(modes)], axis=2),
        paths.modal("thickness_mm"): np.ones(len(faces)),
        paths.modal("fixed_vertices"): np.zeros(v, dtype=bool),
        paths.modal("reconstruction_k"): ks,
    }
    flat = modes.reshape(n_modes, -1)
    coords = {}
    for take in ("smile1", "smile2", "sad1"):
        disp = np.nan_to_num(aligned[take] - neutral)
        q = np.linalg.lstsq(flat.T, disp.ravel(), rcond=None)[0]
        coords[take] = q
        rms = [
            np.sqrt(np.mean(np.sum((disp - (q[:kk] @ flat[:kk]).reshape(v, 3)) ** 2, axis=1)))
            for kk in ks
        ]
        store |= {
            paths.expression(take, "displacement"): disp,
            paths.expression(take, "coordinates"): q,
            paths.expression(take, "reconstruction_rms_mm"): np.asarray(rms),
            paths.expression(take, "synthesized"): (q @ flat).reshape(v, 3),
        }
    smile = np.stack([coords["smile1"], coords["smile2"]])
    store |= {
        paths.modal_statistics("smile", "mean"): smile.mean(axis=0),
        paths.modal_statistics("smile", "std"): smile.std(axis=0, ddof=1),
        paths.modal_statistics("smile", "takes"): np.asarray(["smile1", "smile2"], dtype=object),
        paths.modal_statistics("sad", "mean"): coords["sad1"],
        paths.modal_statistics("sad", "std"): np.full(n_modes, np.nan),
        paths.modal_statistics("sad", "takes"): np.asarray(["sad1"], dtype=object),
    }


@pytest.fixture(scope="module")
def store():
    return synthetic_store()


def _decode(pixels: np.ndarray, scale: ColorScale, n: int = 256) -> np.ndarray:
    """Values whose colour (up to the shading factor) best explains each pixel (N, 3) uint8."""
    t = np.linspace(0, 1, n)
    ramp = scale.colormap(t)[:, :3]
    p = pixels[:: max(1, len(pixels) // 1500)].astype(float) / 255.0  # a sample is enough
    k = (p @ ramp.T) / np.sum(ramp**2, axis=1)  # best shading factor per (pixel, ramp entry)
    resid = np.linalg.norm(p[:, None, :] - k[:, :, None] * ramp[None], axis=2)
    resid[(k < 0.4) | (k > 1.2)] = np.inf
    return scale.vmin + t[resid.argmin(axis=1)] * (scale.vmax - scale.vmin)


def _surface(image: np.ndarray) -> np.ndarray:
    """Pixels that are not the white background."""
    return np.any(image < 245, axis=-1)


# --------------------------------------------------------------------------------------------
# Views
# --------------------------------------------------------------------------------------------
def test_face_view_recovers_up_and_front_of_a_rotated_flat_face():
    rng = np.random.default_rng(4)
    xy, faces, *_ = grid_template()
    rot = Rotation.random(random_state=rng).as_matrix()
    flat = np.column_stack([SCALE_MM * xy, np.full(len(xy), DEPTH_MM)]) @ rot.T
    view = face_view(flat, faces, xy)
    # template -y is up; the camera of the scanner (at -z in camera coordinates) is the front
    np.testing.assert_allclose(view.up, rot @ [0, -1, 0], atol=1e-9)
    np.testing.assert_allclose(view.front, rot @ [0, 0, -1], atol=1e-9)
    np.testing.assert_allclose(view.center, rot @ [0, 0.5 * SCALE_MM, DEPTH_MM], atol=1e-6)


def test_render_is_upright_and_not_mirrored_in_any_frame():
    rng = np.random.default_rng(5)
    xy, faces, *_ = grid_template()
    camera = np.column_stack([SCALE_MM * xy, DEPTH_MM - _height(xy)])
    for _ in range(3):
        rot = Rotation.random(random_state=rng).as_matrix()
        vertices = camera @ rot.T + rng.normal(0, 300, 3)
        # top half red, bottom half blue; image-right half (template +x) gets green added
        rgb = np.where(xy[:, 1:2] < 0.5, [0.9, 0.1, 0.1], [0.1, 0.1, 0.9])
        image = render_view(TexturedMesh(vertices, faces), face_view(vertices, faces, xy), rgb=rgb)
        rows, cols = np.nonzero(_surface(image))
        red = image[rows, cols, 0] > image[rows, cols, 2]
        assert rows[red].mean() < rows[~red].mean() - 40  # red (forehead) above blue (chin)
        rgb[xy[:, 0] > 0.5] = [0.1, 0.9, 0.1]
        image = render_view(TexturedMesh(vertices, faces), face_view(vertices, faces, xy), rgb=rgb)
        rows, cols = np.nonzero(_surface(image))
        green = image[rows, cols, 1] > np.maximum(image[rows, cols, 0], image[rows, cols, 2])
        assert cols[green].mean() > cols[~green].mean() + 40  # template +x on the image's right


def test_rendered_colours_decode_to_the_field_values():
    xy, faces, *_ = grid_template(21, 25)
    vertices = np.column_stack([SCALE_MM * xy, np.full(len(xy), DEPTH_MM)])
    scale = ColorScale(0.0, 10.0, "mm")
    values = np.where(xy[:, 0] < 0, 2.0, 8.0)
    image = render_view(
        TexturedMesh(vertices, faces), face_view(vertices, faces, xy), rgb=scale.rgb(values)
    )
    rows, cols = np.nonzero(_surface(image))
    mid = cols.mean()
    left = image[rows[cols < mid - 20], cols[cols < mid - 20]]
    right = image[rows[cols > mid + 20], cols[cols > mid + 20]]
    np.testing.assert_allclose(np.median(_decode(left, scale)), 2.0, atol=0.15)
    np.testing.assert_allclose(np.median(_decode(right, scale)), 8.0, atol=0.15)


def test_colour_scale_clips_and_marks_nan():
    scale = ColorScale(0.0, 4.0, "mm", cmap="viridis")
    rgb = scale.rgb(np.array([-1.0, 0.0, 2.0, 4.0, 9.0, np.nan]))
    cmap = colormaps["viridis"]
    np.testing.assert_allclose(rgb[:5], cmap(np.array([0, 0, 0.5, 1, 1]))[:, :3])
    np.testing.assert_allclose(rgb[5], (0.55, 0.55, 0.55))


# --------------------------------------------------------------------------------------------
# Store access
# --------------------------------------------------------------------------------------------
def test_takes_by_kind(store):
    assert neutral_take(store) == "neutral"
    assert viseme_takes(store) == ["car", "too"]
    assert expression_takes(store) == ["sad1", "smile1", "smile2"]
    assert example_take(store) == "car"  # the jaw drop moves more than the pucker
    # a take left out of the models by its alignment gate is meshed but not the neutral
    misaligned = dict(store) | {
        paths.mesh("sad3", "vertices"): store[paths.mesh("neutral", "vertices")],
        paths.align("sad3", "ok"): np.bool_(False),
    }
    assert neutral_take(misaligned) == "neutral"


def test_pca_alphas_recover_the_blend_parameters(store):
    alpha = pca_alphas(store, store[paths.pca_blend("pca_blend1")])
    np.testing.assert_allclose(alpha, [0.5, 1.0], atol=1e-9)


def test_pca_alphas_follow_the_stores_sigma_convention(store):
    paper = {
        k: v
        for k, v in store.items()
        if k not in (paths.pca("sigma"), paths.pca("sigma_convention"))
    }
    eig = store[paths.pca("eigenvalues")]
    # a store without /pca/sigma (older) is read in the paper's convention, sqrt(eigenvalue)
    alpha = pca_alphas(paper, store[paths.pca_blend("pca_blend1")])
    np.testing.assert_allclose(
        alpha, [0.5, 1.0] * store[paths.pca("sigma")] / np.sqrt(eig), atol=1e-9
    )
    np.testing.assert_allclose(np.sqrt(eig) / store[paths.pca("sigma")], np.sqrt(2), rtol=1e-12)


def test_eigen_figure_names_its_sigma_and_stays_near_the_models(store):
    fig = fig_eigen(store)
    titles = " ".join(t.get_text() for t in fig.findobj(lambda o: hasattr(o, "get_text")))
    assert "sample std of the coefficients" in titles
    sigma = store[paths.pca("sigma")]
    # the length of the whole field, and what a vertex moves (the audit's F4: "130.9 mm" read
    # as a displacement)
    per_vertex = np.sqrt(np.mean(np.sum((sigma[0] * store[paths.pca("components")][0]) ** 2, 1)))
    assert f"PC1: σ = {sigma[0]:.1f} mm\n{per_vertex:.2f} mm RMS a vertex" in titles
    paper = {k: v for k, v in store.items() if k != paths.pca("sigma")}
    titles = " ".join(
        t.get_text() for t in fig_eigen(paper).findobj(lambda o: hasattr(o, "get_text"))
    )
    assert "√eigenvalue, as in the paper" in titles


def test_blend_titles():
    assert blend_title("man60_eel30") == "0.6 man + 0.3 eel + 0.1 base"
    assert blend_title("too80_eel10_car10") == "0.8 too + 0.1 eel + 0.1 car"
    assert blend_title("car_30") == "0.3 car + 0.7 base"
    assert blend_title("my blend") == "my blend"


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
def test_model_figure_has_three_panels_of_the_face(store):
    fig = fig_model(store)
    panels = figure_panels(fig)
    assert [title for title, _, _ in panels] == ["(a) shaded", "(b) textured", "(c) wireframe"]
    shapes = {image.shape for _, image, _ in panels}
    assert len(shapes) == 1  # cropped alike: one scale
    (shape,) = shapes
    assert 0.5 * PANEL_PX < max(shape[:2]) <= PANEL_PX
    for (_, image, _), fill in zip(panels, (0.5, 0.5, 0.05), strict=True):
        assert _surface(image).mean() > fill  # the face fills the panel (the wireframe: its edges)


def test_expression_figure_maps_a_known_field_to_its_colours(store):
    known = dict(store)
    xy = store[paths.template("vertices2d")]
    for take in expression_takes(store):  # 2 mm on the image's left half, 8 mm on its right half
        magnitude = np.where(xy[:, 0] < 0, 2.0, 8.0)
        known[paths.expression(take, "displacement")] = magnitude[:, None] * np.array(
            [0.6, 0.0, 0.8]
        )
    scale_max = 8.0
    fig = fig_expressions(known)
    image = figure_to_array(fig)
    panel = image[figure_panels(fig)[0][2]]
    r, c = np.nonzero(_surface(panel) & (panel.std(axis=-1) > 12))  # coloured face pixels
    mid = (c.min() + c.max()) / 2
    scale = ColorScale(0.0, scale_max, "")
    left = _decode(panel[r[c < mid - 15], c[c < mid - 15]], scale)
    right = _decode(panel[r[c > mid + 15], c[c > mid + 15]], scale)
    np.testing.assert_allclose(np.median(left) / scale_max, 0.25, atol=0.03)
    np.testing.assert_allclose(np.median(right) / scale_max, 1.0, atol=0.03)


def _car_panel(fig, scale_max):
    """Title of the figure's "car" panel and the median decoded value over the top 30% and the
    bottom 15% of its coloured face pixels."""
    image = figure_to_array(fig)
    title, _, box = next(p for p in figure_panels(fig) if p[0].startswith("car"))
    panel = image[box]
    r, c = np.nonzero(_surface(panel) & (panel.std(axis=-1) > 12))
    top, bottom = r < np.percentile(r, 30), r > np.percentile(r, 85)
    scale = ColorScale(0.0, scale_max, "")
    values = [float(np.median(_decode(panel[r[m], c[m]], scale))) for m in (top, bottom)]
    return title, *values


def test_distance_figure_colours_a_vertex_by_its_distance(store):
    known = dict(store)
    xy = store[paths.template("vertices2d")]
    target = store[paths.align("car", "vertices")].copy()
    model = np.where(np.isfinite(target), target, store[paths.neutral("vertices")])
    far = xy[:, 1] > 1.0  # the lower face is 6 mm off, the rest exact
    model[far] += [6.0, 0.0, 0.0]
    known[paths.viseme("car", "model")] = model
    known[paths.viseme("too", "model")] = np.where(
        np.isfinite(store[paths.align("too", "vertices")]),
        store[paths.align("too", "vertices")],
        store[paths.neutral("vertices")],
    )
    title, top, bottom = _car_panel(fig_distance(known), 6.0)
    assert "RMS" in title
    assert top < 0.6 and bottom > 5.4
    # against the refined correspondence where the store has it (the mesh the motion was
    # measured from), and the takes' consensus before that: the same model is then exact
    refined = dict(known) | {paths.refine("car", "vertices"): model}
    title, top, bottom = _car_panel(fig_distance(refined), 6.0)
    assert top < 0.6 and bottom < 0.6 and "RMS 0.00 mm" in title
    agreed = refined | {paths.consensus("car", "vertices"): target}
    title, top, bottom = _car_panel(fig_distance(agreed), 6.0)
    assert top < 0.6 and bottom > 5.4


def test_click_noise_figure_colours_each_viseme_by_its_error_bar(store):
    known = dict(store)
    xy = store[paths.template("vertices2d")]
    known[paths.viseme("car", "noise_rms_mm")] = np.where(
        xy[:, 1] > 1.0, 2.0, 0.0
    )  # the lower face
    title, top, bottom = _car_panel(fig_click_noise(known), 2.0)
    assert title == "car: 1.00 mm, 10% of the motion"
    assert top < 0.2 and bottom > 1.8
    bare = {k: v for k, v in store.items() if not k.startswith(paths.MOTION_NOISE)}
    assert any("no click-noise" in t.get_text() for t in fig_click_noise(bare).texts)


def test_mask_figure_shows_the_mask_in_orange(store):
    fig = fig_mask(store)
    image = figure_to_array(fig)
    panel = image[figure_panels(fig)[1][2]]
    r, c = np.nonzero(_surface(panel))
    orange = (panel[r, c, 0] > 150) & (panel[r, c, 2] < 60)
    # the suppressed part is the upper face (template y < 0.3): orange pixels lie above the rest
    assert orange.mean() > 0.2
    assert r[orange].mean() < r[~orange].mean()


def test_missing_data_gives_a_figure_that_says_so(store):
    blends = [f"{label}_{pct}" for label in ("car", "too") for pct in (30, 60, 90)]
    dropped = {paths.blend(n) for n in [*blends, "too50_car20"]} | {
        paths.modal_statistics(label, name)
        for label in ("smile", "sad")
        for name in ("mean", "std", "takes")
    }
    assert dropped <= store.keys()
    bare = {
        k: v for k, v in store.items() if k not in dropped and not k.startswith(paths.EXPRESSIONS)
    }
    fig = fig_gradual(bare)
    assert any("no blend" in t.get_text() for t in fig.texts)
    figs = stage_figures(bare, "modal")
    assert any("no expression" in t.get_text() for t in figs["modal_synthesis"].texts)


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------
def _write_store(path, data):
    part = path.parent / "part.h5"
    write_part(part, data)
    merge_parts(path, [part], "s01", "0" * 64)


def test_the_store_mapping_reads_an_hdf5_store(tmp_path, store):
    """(write_stage_figures from such a store: the next test.)"""
    path = tmp_path / "s01.h5"
    _write_store(path, store)
    with StoreMapping(path) as mapping:
        assert set(mapping) == set(store)
        assert list(mapping[paths.pca("takes")]) == ["neutral", "car", "too"]


def test_one_job_draws_every_stage_as_the_stages_alone(tmp_path, store):
    """write_figures draws every stage from one opening of the store, each figure once: each
    figure drawn (not an empty canvas) at its figure's size, the same pixels as matplotlib's
    savefig (checked for two stages), and a stage's the same as write_stage_figures of that
    stage alone (nothing of the stages drawn before leaks into it); the PNGs are RGB (savefig's
    alpha is opaque everywhere) written at the set zlib level."""
    path = tmp_path / "s01.h5"
    _write_store(path, store)
    stages = list(STAGE_FIGURES)
    declared = [tmp_path / "all" / f"{s}.png" for st in stages for s in figure_names(st)]
    timings = {}
    together = write_figures(path, tmp_path / "all", stages, declared, timings)
    assert together == declared
    assert set(timings) == set(stages) and all(t > 0 for t in timings.values())
    # the oracle: matplotlib's own savefig of each figure (its two drawings, zlib level 6)
    sizes = {}
    for st in ("fit", "morph"):
        for stem, fig in stage_figures(store, st).items():
            fig.savefig(tmp_path / f"{stem}.png", dpi=DPI, facecolor="white")
            sizes[stem] = fig.get_size_inches() * DPI
    for a in together:
        image = np.asarray(Image.open(a))
        assert image.ndim == 3 and image.shape[2] == 3, a.name
        assert image[..., :3].std() > 20, a.name  # drawn, not an empty canvas
        if a.stem in sizes:
            w, h = sizes[a.stem]
            assert abs(image.shape[0] - h) <= 1 and abs(image.shape[1] - w) <= 1, a.name
            oracle = np.asarray(Image.open(tmp_path / a.name))
            assert (oracle[..., 3] == 255).all(), a.name
            np.testing.assert_array_equal(image, oracle[..., :3])
    alone = write_stage_figures(path, tmp_path / "morph", "morph")
    assert [p.name for p in alone] == [p.name for p in declared if p.name.startswith("morph_")]
    for b in alone:
        np.testing.assert_array_equal(
            np.asarray(Image.open(b)), np.asarray(Image.open(tmp_path / b.name))[..., :3]
        )
    # level 1, not Pillow's default 6: the zlib header's FLEVEL is 0 (levels 0-1), not 2
    assert {_zlib_flevel(p) for p in together} == {0}
    with pytest.raises(InputError, match="differ from the figures drawn"):
        write_figures(path, tmp_path / "all", stages, declared[:-1])


def _zlib_flevel(png) -> int:
    """The compression-level field (FLEVEL, RFC 1950) of a PNG file's zlib stream."""
    data = png.read_bytes()
    at = data.index(b"IDAT")  # the first image-data chunk: the zlib header follows its type
    return data[at + 5] >> 6


def test_bad_input(tmp_path, store):
    with pytest.raises(InputError, match="stage: expected one of"):
        figure_names("render")
    with pytest.raises(InputError, match="store not found"):
        write_stage_figures(tmp_path / "none.h5", tmp_path, "fit")
    missing = {k: v for k, v in store.items() if k != paths.neutral("vertices")}
    with pytest.raises(
        InputError,
        match=rf"dataset {re.escape(paths.neutral('vertices'))} is missing \(needed for the mask figure\)",
    ):
        fig_mask(missing)
    car = paths.viseme("car", "model")
    short = dict(store) | {car: store[car][:-1]}
    with pytest.raises(InputError, match=rf"{re.escape(car)}: expected shape"):
        fig_distance(short)
    two = dict(store) | {paths.mesh("extra", "vertices"): store[paths.mesh("neutral", "vertices")]}
    with pytest.raises(InputError, match="exactly one neutral take"):
        fig_model(two)
    coef = paths.pca("coefficients")
    rows = dict(store) | {coef: store[coef][:-1]}
    with pytest.raises(InputError, match=rf"{re.escape(coef)}: expected 3 rows"):
        stage_figures(rows, "morph")
    ks = dict(store) | {paths.modal("reconstruction_k"): np.array([1, 2])}
    with pytest.raises(InputError, match=r"reconstruction_rms_mm: expected shape \(2,\)"):
        stage_figures(ks, "modal")
    fid = paths.template("fiducials/names")
    names = dict(store) | {fid: store[fid][:-1]}
    with pytest.raises(InputError, match="names and indices differ in length"):
        stage_figures(names, "motion")
    xy, faces, *_ = grid_template()
    with pytest.raises(InputError, match="vertices2d: expected shape"):
        face_view(np.zeros((len(xy), 3)), faces, xy[:-1])
    with pytest.raises(InputError, match="fewer than 3 valid vertices"):
        face_view(np.full((len(xy), 3), np.nan), faces, xy)
    with pytest.raises(InputError, match="faces: indices must lie"):
        face_view(np.zeros((4, 3)), faces, xy[:4])


def test_base_faces_undo_the_template_subdivision():
    from scan2morph.render.fit_figures import base_faces
    from scan2morph.template import subdivide

    xy, faces, *_ = grid_template(5, 6)
    once = subdivide(xy, faces)
    twice = subdivide(once[0], once[1])
    np.testing.assert_array_equal(base_faces(once[1]), faces)
    np.testing.assert_array_equal(base_faces(twice[1]), faces)
    assert base_faces(faces) is None  # not a subdivision
    assert base_faces(np.roll(once[1], 1, axis=0)) is None


def test_the_workflow_names_figures_without_loading_the_renderer():
    """render.names (imported while the workflow is parsed) matches the figure functions and
    loads neither pyrender nor matplotlib (2.5-3 CPU-s of every Snakemake start-up)."""
    import subprocess
    import sys

    code = (
        "import sys; from scan2morph.render.names import FIGURE_NAMES; "
        "print(any(m in sys.modules for m in ('pyrender', 'matplotlib', 'open3d')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    assert {s: tuple(f) for s, f in STAGE_FIGURES.items()} == FIGURE_NAMES


@pytest.mark.parametrize("n_panels", [5, 18])
def test_panel_figure_puts_each_panel_pixel_for_pixel_in_its_own_box(n_panels):
    """The grid laid out without a layout engine: every image is the input cropped and resized
    (Lanczos, aspect kept), drawn unresampled where figure_panels says, inside the figure, in
    boxes that do not overlap, one size for all, each under its title, all below the figure's
    title (a short grid and a tall one)."""
    rng = np.random.default_rng(3)
    images = []
    for _ in range(n_panels):
        image = np.full((PANEL_PX, PANEL_PX, 3), 255, np.uint8)
        image[60:300, 100:260] = rng.integers(0, 250, (240, 160, 3))
        images.append(image)
    panels = [Panel(im, f"panel {i}\nsecond line") for i, im in enumerate(images)]
    fig = panel_figure(
        panels,
        ncols=3,
        title="A grid",
        scale=ColorScale(0.0, 1.0, "value (mm)"),
        legend=[((1.0, 0.0, 0.0), "red")],
        row_labels=[f"row {i}" for i in range(-(-n_panels // 3))],
    )
    drawn = figure_to_array(fig)
    found = figure_panels(fig)
    assert [t for t, _, _ in found] == [p.title for p in panels]
    assert len({im.shape for _, im, _ in found}) == 1
    boxes = []
    for (_, image, (rows, cols)), source in zip(found, images, strict=True):
        assert 0 <= rows.start and rows.stop <= drawn.shape[0]
        assert 0 <= cols.start and cols.stop <= drawn.shape[1]
        np.testing.assert_array_equal(drawn[rows, cols], image)  # drawn unresampled
        crop = source[54:306, 94:266]  # crop_panels: the drawn part and its 6-pixel margin
        h, w = image.shape[:2]
        assert abs(w / h - crop.shape[1] / crop.shape[0]) < 0.02
        oracle = np.asarray(Image.fromarray(crop).resize((w, h), Image.Resampling.LANCZOS))
        np.testing.assert_array_equal(image, oracle)
        boxes.append((rows, cols))
    for i, (r1, c1) in enumerate(boxes):
        for r2, c2 in boxes[i + 1 :]:
            overlap_r = min(r1.stop, r2.stop) > max(r1.start, r2.start)
            overlap_c = min(c1.stop, c2.stop) > max(c1.start, c2.start)
            assert not (overlap_r and overlap_c)
    renderer = fig.canvas.get_renderer()
    height = drawn.shape[0]
    top = next(t for t in fig.texts if t.get_text() == "A grid").get_window_extent(renderer)
    for (title, _, (rows, cols)), text in zip(
        found, [t for t in fig.texts if t.get_text().startswith("panel")], strict=True
    ):
        box = text.get_window_extent(renderer)
        assert text.get_text() == title
        assert height - box.y0 <= rows.start  # the title's bottom above its image's top
        assert box.y1 <= height and cols.start <= (box.x0 + box.x1) / 2 <= cols.stop
        assert box.y1 < top.y0  # under the figure's title


def test_grid_layout_gives_one_size_and_leaves_the_margins():
    panels = [Panel(np.zeros((200, 100, 3), np.uint8), "t")] * 4 + [Panel(None)]
    layout = grid_layout(panels, (2, 3), (6.0, 5.0), margins=(0.4, 1.0, 0.3))
    rects = [r for r in layout.rects if r is not None]
    assert layout.rects[-1] is None and len(rects) == 4
    assert {(w, h) for _, _, w, h in rects} == {rects[0][2:]}
    w, h = rects[0][2:]
    assert abs(w / h - 0.5) < 0.01
    assert min(x for x, _, _, _ in rects) >= 0.4 * DPI  # the row labels' band
    assert max(x + w for x, _, _, _ in rects) <= (6.0 - 1.0) * DPI  # the colour bar's
    assert min(y for _, y, _, _ in rects) >= 0.3 * DPI  # the legend's
    assert layout.grid_right <= 5.0 / 6.0


def test_bars_draw_what_axes_bar_draws():
    """One collection for many bars: the same pixels as a bar per patch, NaN bars left out."""
    x = np.arange(1, 41)
    heights = np.sin(x / 3.0) * 2.0
    heights[7] = np.nan
    pictures = []
    for draw in ("bar", "bars"):
        fig, ax = subplots(figsize=(4.0, 2.0))
        if draw == "bar":
            ax.bar(x, heights, width=0.8, color="tab:blue")
        else:
            bars(ax, x, heights, width=0.8, color="tab:blue")
        ax.axhline(0, color="0.3", lw=0.5)
        pictures.append(figure_to_array(fig))
        limits = ax.get_ylim()
    np.testing.assert_array_equal(*pictures)
    assert limits[0] < -1.9 and limits[1] > 1.9
    fig, ax = subplots(figsize=(2.0, 2.0))
    bars(ax, [1, 2], [1.0, 3.0])
    assert ax.get_ylim()[0] == 0.0  # stops at 0 as bar's does
    axes_off(ax)
    assert len(ax.xaxis.get_majorticklocs()) == 0 and len(ax.yaxis.get_majorticklocs()) == 0


def test_opaque_rgba_draws_as_the_rgb_image_within_a_level():
    rng = np.random.default_rng(5)
    rgb = rng.integers(0, 256, (48, 64, 3)).astype(np.uint8)
    rgba = opaque_rgba(rgb)
    assert rgba.shape == (48, 64, 4) and (rgba[..., 3] == 255).all()
    np.testing.assert_array_equal(rgba[..., :3], rgb)
    grey = rng.random((8, 8))
    assert opaque_rgba(grey) is grey or np.shares_memory(opaque_rgba(grey), grey)
    drawn = []
    for image in (rgb, rgba):
        fig, ax = subplots(figsize=(2.0, 1.6))
        ax.imshow(image, interpolation="bilinear")
        ax.set_xlim(5.3, 50.7)
        ax.set_ylim(40.2, 3.9)
        drawn.append(figure_to_array(fig).astype(int))
    assert np.abs(drawn[0] - drawn[1]).max() <= 1


# --------------------------------------------------------------------------------------------
# Audit 12: what the figures say
# --------------------------------------------------------------------------------------------
def _texts(fig) -> list[str]:
    return [t.get_text() for t in fig.findobj(lambda o: hasattr(o, "get_text")) if t.get_text()]


def _colorbar(fig):
    (bar,) = [ax._colorbar for ax in fig.axes if getattr(ax, "_colorbar", None) is not None]
    return bar


def test_eigen_row_labels_stay_in_their_rows_and_the_figure(store):
    """The upright row labels ("PC1: σ = 130.9 mm, 3.19 mm RMS a vertex") ran into each other
    and off the figure's top and bottom on one line."""
    fig = fig_eigen(store)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    labels = [t for t in fig.texts if t.get_rotation() == 90 and t.get_text().startswith("PC")]
    assert len(labels) == len(store[paths.pca("components")]) >= 2
    boxes = sorted((t.get_window_extent(renderer) for t in labels), key=lambda b: -b.y1)
    for box in boxes:
        assert box.x0 >= 0 and box.y0 >= 0 and box.y1 <= fig.bbox.height
    for upper, lower in zip(boxes, boxes[1:], strict=False):
        assert lower.y1 < upper.y0  # no overlap
    images = figure_panels(fig)
    left = min(box[1].start for _, _, box in images)
    assert max(b.x1 for b in boxes) < left  # clear of the panels


def test_colour_scale_clipped_at_a_percentile_has_an_arrow():
    values = np.array([0.0, 1.0, 2.0, 9.0, np.nan])
    assert ColorScale.clipped(0.0, 2.0, "x", values).extend == "max"
    assert ColorScale.clipped(0.0, 9.0, "x", values).extend == "neither"
    assert ColorScale.clipped(1.0, 2.0, "x", values).extend == "both"


def test_field_figures_mark_the_values_above_their_scale(store):
    """The field figures end their scale at the 99th percentile: the colour bar's arrow says
    the top colour means "this much or more" (before, the bar ended flat at 0.8 mm while car's
    click-noise error went above it)."""
    known = dict(store)
    xy = store[paths.template("vertices2d")]
    spike = np.where(xy[:, 1] > 1.0, 0.5, 0.0)
    spike[np.argmax(xy[:, 1])] = 50.0  # one vertex far above the 99th percentile
    known[paths.viseme("car", "noise_rms_mm")] = spike
    assert _colorbar(fig_click_noise(known)).extend == "max"
    assert _colorbar(fig_expressions(store)).extend == "max"
    assert _colorbar(fig_synthesis(store)).extend == "max"
    assert _colorbar(fig_modes(store)).extend == "neither"  # 0..1 of each mode's maximum


def test_synthesis_titles_give_the_differences_rms(store):
    """The |synth. - meas.| column is near blank on the fields' scale: its title says how big."""
    fig = fig_synthesis(store)
    for take in expression_takes(store):
        d = store[paths.expression(take, "displacement")]
        s = store[paths.expression(take, "synthesized")]
        rms = np.sqrt(np.nanmean(np.sum((s - d) ** 2, axis=1)))
        assert f"{take}: |synth. - meas.|\nRMS {rms:.2f} mm" in _texts(fig)


def test_mode_figure_says_when_the_modes_are_orthonormalised_per_vertex(store):
    """With coordinates "vertex" (the default skin preset) the stored modes are not the natural
    ones and their frequencies are Rayleigh quotients, out of order: the title said "Natural
    mode shapes" over "mode 4, 215.3 Hz" after "mode 2, 277.1 Hz"."""
    vertex = dict(store) | {
        paths.modal("physics"): json.dumps({"preset": "skin", "coordinates": "vertex"})
    }
    title = fig_modes(vertex)._suptitle.get_text()
    assert "Natural" not in title and "orthonormalised per vertex" in title
    assert "Rayleigh" in title
    mass = dict(store) | {paths.modal("physics"): json.dumps({"coordinates": "mass"})}
    assert fig_modes(mass)._suptitle.get_text() == "Natural mode shapes of the neutral face"
    assert fig_modes(store)._suptitle.get_text() == "Natural mode shapes of the neutral face"


def test_reconstruction_legend_explains_the_dashed_lines(store):
    known = dict(store)
    for take in expression_takes(store):
        rms = store[paths.expression(take, "reconstruction_rms_mm")]
        known[paths.expression(take, "reconstruction_normal_rms_mm")] = 0.5 * rms
    legend = fig_reconstruction(known).axes[0].get_legend()
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts[: len(expression_takes(store))] == expression_takes(store)
    assert any("dashed" in t and "normals" in t for t in texts)
    # without the normal parts, no dashed line and no legend entry for one
    plain = fig_reconstruction(store).axes[0].get_legend()
    assert not any("dashed" in t.get_text() for t in plain.get_texts())


def test_landmark_figure_names_the_image_each_modality_is_seen_in(store):
    """A mesh scan's landmarks sit on its virtual-camera render, a stereo take's on its left
    image: the title said "color image" for every subject."""

    def titled(modality):
        known = dict(store)
        if modality is not None:
            for take in ("neutral", example_take(store)):
                known[paths.camera(take, "modality")] = np.asarray(modality, dtype=object)
        fig = fig_landmarks(known)
        return fig._suptitle.get_text(), [ax.get_ylabel() for ax in fig.axes if ax.get_ylabel()]

    assert titled("mesh") == (
        "Template fitted to the virtual-camera render",
        ["virtual-camera render"] * 2,
    )
    assert titled("stereo")[0] == "Template fitted to the left image"
    assert titled("rgbd")[0] == "Template fitted to the color image"
    assert titled(None)[0] == "Template fitted to the color image"


def test_neutral_is_not_named_twice(store):
    assert neutral_take(store) == "neutral"
    assert "neutral (neutral)" not in " ".join(_texts(fig_alignment(store)))
    assert fig_model(store)._suptitle.get_text() == (
        "3D face model of the neutral take, scanner frame"
    )


def test_statistics_titles_count_takes_in_the_singular_too(store):
    titles = [ax.get_title(loc="left") for ax in fig_statistics(store).axes]
    assert "sad: mean ± std over 1 take (one take: no std)" in titles
    assert "smile: mean ± std over 2 takes" in titles


def test_takes_figure_names_the_virtual_camera_only_with_mesh_takes(store):
    """The audit's finding 11: the takes figure said "(mesh takes: rendered by the virtual
    camera)" on every subject, also one without mesh takes."""
    from scan2morph.render.fit_figures import fig_takes

    title = fig_takes(store)._suptitle.get_text().replace("\n", " ")
    assert "virtual camera" not in title and title.startswith("Each take's image and landmarks;")
    meshed = dict(store) | {paths.camera("car", "modality"): "mesh"}
    title = fig_takes(meshed)._suptitle.get_text().replace("\n", " ")
    assert "(mesh takes: rendered by the virtual camera)" in title


def test_a_small_contribution_ratio_keeps_two_digits():
    """The audit's finding 14: PC5's bar read "0.000 (46.9 mm²)" where Table 1 gives 0.045%."""
    from scan2morph.render.morph_figures import _share

    assert [_share(c) for c in (0.83092, 0.01, 0.00045, 0.0)] == [
        "0.831",
        "0.010",
        "0.00045",
        "0.000",
    ]


def test_takes_figure_is_shown_at_its_own_size_in_the_report(store):
    """The figures audit (its finding 11): five takes a row made the figure 1725 px wide, shown
    at two thirds in the report's 1200 px page (its padding 2 x 1.5 rem): 7 pt titles at 5 pt."""
    from scan2morph.render.fit_figures import fig_takes
    from scan2morph.render.views import DPI
    from tests.support.workflow_api import REPO

    css = (REPO / "src/scan2morph/report/templates/report.css").read_text()
    page_px = int(re.search(r"max-width:(\d+)px;padding:0 1.5rem", css).group(1)) - 2 * 24
    fig = fig_takes(store)
    assert fig.get_size_inches()[0] * DPI <= page_px


def test_detected_landmarks_get_a_confidence_colour_bar(store):
    """The figures audit's finding 12: detected points are coloured by confidence, said only
    in words. With a detected take the takes and landmark figures have a 0-1 colour bar; with
    clicked takes alone none."""
    from scan2morph.render.fit_figures import fig_landmarks, fig_takes

    def bars(fig):
        return [ax._colorbar for ax in fig.axes if getattr(ax, "_colorbar", None) is not None]

    assert bars(fig_takes(store)) == [] and bars(fig_landmarks(store)) == []
    neutral = neutral_take(store)
    detected = dict(store) | {paths.landmark_confidence(neutral): np.linspace(0.2, 0.9, 68)}
    for fig in (fig_takes(detected), fig_landmarks(detected)):
        (bar,) = bars(fig)
        assert bar.ax.get_ylabel() == "landmark confidence"
        assert (bar.vmin, bar.vmax) == (0.0, 1.0)
