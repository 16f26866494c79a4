"""Figures of alignment and viseme motion (Yano and Harada, Fig. 5-10 and 17)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from scan2morph.geometry import TexturedMesh
from scan2morph.motion.uncertainty import noise_by_take
from scan2morph.render.source import (
    example_take,
    fiducials,
    mesh,
    need,
    neutral_take,
    neutral_view,
    source_of,
    template_faces,
    viseme_takes,
)
from scan2morph.render.views import (
    ColorScale,
    Panel,
    face_view,
    frame_view,
    message_figure,
    panel_figure,
    render_view,
)
from scan2morph.store import paths
from scan2morph.template.mesh import ICP_POINTS

#: Radius of the coloured spot that marks a point on a mesh, mm.
SPOT_MM = 5.0
#: Plain surface colour (sRGB) behind marks and masks.
SKIN_RGB = (0.80, 0.76, 0.72)
#: The two meshes of an overlay: neutral (blue) and the other take (orange).
PAIR_RGB = ((0.25, 0.50, 0.90), (0.95, 0.55, 0.15))
#: Suppressed vertices of the stencil mask (orange, as the paper) and the rest (dark grey).
MASK_RGB, UNMASKED_RGB = (1.0, 0.55, 0.0), (0.22, 0.22, 0.22)
#: Seed vertices of the mask.
SEED_RGB = (0.85, 0.05, 0.05)
#: Yaw of the profile views, degrees.
PROFILE_DEG = 90.0


def _spots(vertices: np.ndarray, centers: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """(V, 3) sRGB: skin, and each centre's colour within SPOT_MM of it."""
    rgb = np.tile(SKIN_RGB, (len(vertices), 1))
    d = np.linalg.norm(vertices[:, None, :] - centers[None, :, :], axis=2)
    d = np.where(np.isfinite(d), d, np.inf)
    near = d.argmin(axis=1)
    hit = d[np.arange(len(vertices)), near] <= SPOT_MM
    rgb[hit] = colors[near[hit]]
    return rgb


def fig_point_pairs(store: Mapping[str, np.ndarray]) -> Figure:
    """The six point pairs of the initial alignment on the neutral and one other take (Fig. 5).

    Each pair has one colour on both meshes; each mesh is shown in its own scanner frame.
    """
    what = "the point-pair figure"
    faces = template_faces(store, what)
    fid = fiducials(store)
    names = [n for n in ICP_POINTS if n in fid]
    if not names:
        return message_figure(
            "Point pairs for the initial alignment", "no ICP point is a fiducial of this template"
        )
    colors = colormaps["tab10"](np.arange(len(names)))[:, :3]
    xy = need(store, paths.template("vertices2d"), what)
    takes = [neutral_take(store)] + [t for t in [example_take(store)] if t is not None]
    panels = []
    for take in takes:
        vertices = mesh(store, paths.mesh(take, "vertices"), what)
        idx = np.array([fid[n] for n in names])
        rgb = _spots(vertices, vertices[idx], colors)
        view = face_view(vertices, faces, xy, source=source_of(store))
        panels.append(
            Panel(
                render_view(TexturedMesh(vertices, faces), view, rgb=rgb), f"{take} (scanner frame)"
            )
        )
    legend = [(tuple(c), n.replace("_", " ")) for c, n in zip(colors, names, strict=True)]
    return panel_figure(
        panels,
        ncols=len(panels),
        title="Point pairs for the initial rigid alignment",
        legend=legend,
        legend_ncol=3,
    )


def _pair(
    a: np.ndarray, b: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two meshes as one: vertices, faces and the pair colours."""
    vertices = np.vstack([a, b])
    both = np.vstack([faces, faces + len(a)])
    rgb = np.vstack([np.tile(PAIR_RGB[0], (len(a), 1)), np.tile(PAIR_RGB[1], (len(b), 1))])
    return vertices, both, rgb


def fig_alignment(store: Mapping[str, np.ndarray]) -> Figure:
    """The neutral and one other take before (scanner frames) and after rigid alignment (Fig. 6).

    Rows: before, after; columns: frontal and profile view of the neutral frame.
    """
    what = "the alignment figure"
    take = example_take(store)
    if take is None:
        return message_figure(
            "Rigid alignment", "the store has no viseme or expression take to align"
        )
    faces = template_faces(store, what)
    neutral = neutral_take(store)
    base = mesh(store, paths.align(neutral, "vertices"), what)
    rows = {
        "before (scanner frames)": mesh(store, paths.mesh(take, "vertices"), what),
        "after alignment": mesh(store, paths.align(take, "vertices"), what),
    }
    direction = neutral_view(store, what)
    panels = []
    for other in rows.values():
        vertices, both, rgb = _pair(base, other, faces)
        view = frame_view(direction, [base, other], faces)
        for yaw, side in ((0.0, "front"), (PROFILE_DEG, "profile")):
            panels.append(
                Panel(render_view(TexturedMesh(vertices, both), view, rgb=rgb, yaw_deg=yaw), side)
            )
    legend = [(PAIR_RGB[0], _neutral_name(neutral)), (PAIR_RGB[1], take)]
    return panel_figure(
        panels,
        ncols=2,
        title=f"Rigid alignment of {take} to {neutral}",
        legend=legend,
        row_labels=list(rows),
    )


def _neutral_name(take: str) -> str:
    """The neutral take as a legend names it: ``smile0 (neutral)``, and ``neutral`` alone when
    the take is called so (not ``neutral (neutral)``)."""
    return take if take == "neutral" else f"{take} (neutral)"


def fig_mask(store: Mapping[str, np.ndarray]) -> Figure:
    """Seed vertices (on the Dijkstra paths) and the stencil mask on the neutral (Fig. 7)."""
    what = "the mask figure"
    faces = template_faces(store, what)
    base = mesh(store, paths.neutral("vertices"), what)
    suppressed = need(store, paths.mask("suppressed"), what).astype(bool)
    seeds = need(store, paths.mask("seeds"), what).astype(np.int64)
    view = neutral_view(store, what)
    seed_rgb = np.tile(SKIN_RGB, (len(base), 1))
    seed_rgb[seeds] = SEED_RGB
    mask_rgb = np.where(suppressed[:, None], MASK_RGB, UNMASKED_RGB)
    panels = [
        Panel(
            render_view(TexturedMesh(base, faces), view, rgb=seed_rgb),
            f"(a) seeds: {len(seeds)} vertices on the paths",
        ),
        Panel(
            render_view(TexturedMesh(base, faces), view, rgb=mask_rgb),
            f"(b) mask: {suppressed.sum()} of {len(base)} vertices",
        ),
    ]
    legend = [(SEED_RGB, "seed"), (MASK_RGB, "suppressed (motion zeroed)"), (UNMASKED_RGB, "free")]
    return panel_figure(panels, ncols=2, title="Stencil mask on the neutral model", legend=legend)


def _viseme_fields(
    store: Mapping[str, np.ndarray],
    what: str,
    field,
    label: str,
    title: str,
) -> Figure:
    """Each viseme model coloured by a per-vertex field (mm), one shared scale to its 99th
    percentile (the colour bar's arrow: values above it take its top colour);
    ``field(take, model)`` gives the (V,) values and the panel title."""
    takes = viseme_takes(store)
    if not takes:
        return message_figure(title, "the store has no viseme takes")
    faces = template_faces(store, what)
    models = {take: mesh(store, paths.viseme(take, "model"), what) for take in takes}
    values, titles = {}, {}
    for take in takes:
        values[take], titles[take] = field(take, models[take])
    finite = np.concatenate([d[np.isfinite(d)] for d in values.values()])
    vmax = float(np.percentile(finite, 99)) if finite.size else 1.0
    scale = ColorScale.clipped(0.0, max(vmax, 1e-3), label, finite)
    view = frame_view(neutral_view(store, what), list(models.values()), faces)
    panels = [
        Panel(
            render_view(TexturedMesh(models[t], faces), view, rgb=scale.rgb(values[t])), titles[t]
        )
        for t in takes
    ]
    return panel_figure(panels, ncols=min(len(panels), 5), title=title, scale=scale)


def fig_distance(store: Mapping[str, np.ndarray]) -> Figure:
    """Each viseme model coloured by its distance to the measured take it was made from
    (:func:`measured_take`; Fig. 9, 10)."""
    what = "the viseme distance figure"

    def distance(take, model):
        d = np.linalg.norm(model - measured_take(store, take, what), axis=1)
        rms = float(np.sqrt(np.nanmean(d**2))) if np.isfinite(d).any() else float("nan")
        return d, f"{take}: RMS {rms:.2f} mm"

    return _viseme_fields(
        store,
        what,
        distance,
        "distance to the measured take (mm)",
        "Viseme models (neutral + processed motion) against the measured takes",
    )


def measured_take(store: Mapping[str, np.ndarray], take: str, what: str) -> np.ndarray:
    """(V, 3) mm, neutral frame: the take's mesh its motion was measured from: the takes'
    consensus where it moved it, else the refined correspondence, else the aligned fit (a
    store without refinement). The aligned fit alone would show how far the refinement moved
    the landmarks' fit, not the model's error."""
    refined = paths.refined(take, store)(take, "vertices")
    return mesh(store, refined if refined in store else paths.align(take, "vertices"), what)


def fig_click_noise(store: Mapping[str, np.ndarray]) -> Figure:
    """Each viseme model coloured by the click-noise error of its motion (``motion_noise``)."""
    what = "the click-noise figure"
    title = "Error that the landmark clicks add to each viseme's motion"
    bars = noise_by_take(store)
    if not bars:
        return message_figure(title, "the store has no click-noise estimate")
    if paths.motion_noise("click_noise_px") in store:
        title += f" (clicks of {float(store[paths.motion_noise('click_noise_px')]):.2f} px)"

    def noise(take, model):
        values = need(store, paths.viseme(take, "noise_rms_mm"), what)
        if take not in bars:
            return values, take
        bar = bars[take]
        if not np.isfinite(bar["rms_error_mm"]):  # every refit refused (the stage's warning)
            return values, f"{take}: no error bar"
        return (
            values,
            f"{take}: {bar['rms_error_mm']:.2f} mm, {100 * bar['relative']:.0f}% of the motion",
        )

    return _viseme_fields(store, what, noise, "click-noise error (mm)", title)


def fig_visemes(store: Mapping[str, np.ndarray]) -> Figure:
    """The neutral base model and every viseme model, shaded and textured (Fig. 10, 17)."""
    what = "the viseme models figure"
    faces = template_faces(store, what)
    neutral = neutral_take(store)
    shapes = {f"{neutral} (base)": mesh(store, paths.neutral("vertices"), what)}
    shapes |= {take: mesh(store, paths.viseme(take, "model"), what) for take in viseme_takes(store)}
    uv = need(store, paths.mesh(neutral, "uv"), what)
    color = need(store, paths.range_image(neutral, "color"), what)
    view = frame_view(neutral_view(store, what), list(shapes.values()), faces)
    shaded = [Panel(render_view(TexturedMesh(v, faces), view), name) for name, v in shapes.items()]
    textured = [
        Panel(render_view(TexturedMesh(v, faces, uv, color), view), "") for v in shapes.values()
    ]
    return panel_figure(
        shaded + textured,
        ncols=len(shapes),
        title="Face models with viseme control: base model and viseme models (neutral texture)",
    )


#: Figure name -> function, in the order the report shows them.
FIGURES = {
    "point_pairs": fig_point_pairs,
    "alignment": fig_alignment,
    "mask": fig_mask,
    "distance": fig_distance,
    "click_noise": fig_click_noise,
    "visemes": fig_visemes,
}
