"""Figures of template fitting (Yano and Harada, Fig. 1-4): template, fitted meshes, 3D model."""

from __future__ import annotations

from collections.abc import Mapping
from textwrap import fill

import numpy as np
from matplotlib.figure import Figure
from matplotlib.tri import Triangulation

from scan2morph.errors import InputError
from scan2morph.geometry import TexturedMesh
from scan2morph.render.source import (
    example_take,
    fiducials,
    groups,
    mesh,
    need,
    neutral_take,
    source_of,
    template_faces,
)
from scan2morph.render.views import (
    Panel,
    axes_off,
    face_view,
    opaque_rgba,
    panel_figure,
    render_view,
    subplots,
)
from scan2morph.store import paths
from scan2morph.store.warnings import landmark_source
from scan2morph.template.mesh import CLOSED_MOUTH, INNER_LIP_CORNERS, INNER_LIPS

#: Colour of the wireframe's edges (sRGB).
WIRE_RGB = np.array([0.15, 0.15, 0.2])
#: Margin around the face when an image is cropped to it, as a share of the face's extent.
CROP_MARGIN = 0.08
#: The image a take's landmarks and fit are drawn on, by modality (``/takes/{t}/camera/modality``);
#: others (range, RGB-D): the color image.
IMAGE_NAMES = {"stereo": "left image", "mesh": "virtual-camera render"}


def image_name(store: Mapping, take: str) -> str:
    """What a take's ``range_image/color`` is: its color image, a stereo pair's left image or a
    mesh scan's render through the virtual camera."""
    return IMAGE_NAMES.get(_text(store, paths.camera(take, "modality"), "range"), "color image")


def _valid_faces(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return faces[np.all(np.isfinite(points[faces]), axis=(1, 2))]


def fig_template(store: Mapping[str, np.ndarray]) -> Figure:
    """The 2D template mesh with its fiducials (Fig. 1a).

    The paper's 20 closed-mouth feature points are red, the inner-lip points added for an open
    mouth orange, the named points that later stages use (ICP pairs, mask path ends) green, the
    other iBUG vertices small grey dots.
    """
    xy = need(store, paths.template("vertices2d"), "the template figure").astype(float)
    faces = template_faces(store, "the template figure")
    fid = fiducials(store)
    ibug = {int(n[4:]): i for n, i in fid.items() if n.startswith("ibug") and n[4:].isdigit()}
    named = {n: i for n, i in fid.items() if not (n.startswith("ibug") and n[4:].isdigit())}
    coarse = base_faces(faces)
    shown = faces if coarse is None else coarse
    fig, ax = subplots(figsize=(5.4, 6.2))
    ax.triplot(Triangulation(xy[:, 0], xy[:, 1], shown), color="0.6", lw=0.35)
    named_idx = list(named.values())
    dots = [
        (
            [i for n, i in ibug.items() if n not in CLOSED_MOUTH + INNER_LIPS],
            "0.35",
            6,
            "other iBUG points",
        ),
        (
            [ibug[n] for n in CLOSED_MOUTH if n in ibug],
            "tab:red",
            28,
            f"closed-mouth fiducials ({len(CLOSED_MOUTH)})",
        ),
        (
            [ibug[n] for n in INNER_LIPS if n in ibug and n not in INNER_LIP_CORNERS],
            "tab:orange",
            22,
            f"inner lips, open mouth (+{len(INNER_LIPS) - len(INNER_LIP_CORNERS)})",
        ),
        (
            [ibug[n] for n in INNER_LIP_CORNERS if n in ibug],
            "tab:purple",
            22,
            f"inner-lip corners, open_corners set only (+{len(INNER_LIP_CORNERS)})",
        ),
    ]
    for idx, color, size, label in dots:
        if idx:
            ax.scatter(
                xy[idx, 0], xy[idx, 1], s=size, c=color, zorder=3, label=label, edgecolors="none"
            )
    if named_idx:  # rings, so that a named point that is also an iBUG fiducial shows both
        ax.scatter(
            xy[named_idx, 0],
            xy[named_idx, 1],
            s=60,
            facecolors="none",
            edgecolors="tab:green",
            linewidths=1.2,
            zorder=4,
            label="named points (ICP pairs, mask paths)",
        )
    ax.set_aspect("equal")
    ax.invert_yaxis()
    ax.set_xlabel("x (half outer-eye distance)")
    ax.set_ylabel("y (down)")
    n_v = int(shown.max()) + 1
    level = (
        f"\n(base level; {len(xy)} vertices, {len(faces)} faces after subdivision)"
        if coarse is not None
        else ""
    )
    ax.set_title(
        f"2D template with fiducials: {n_v} vertices, {len(shown)} faces{level}", fontsize=9
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=7, frameon=False)
    return fig


def _crop_box(points: np.ndarray, shape: tuple[int, ...]) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) pixel box around finite points with a margin, inside the image."""
    p = points[np.all(np.isfinite(points), axis=1)]
    lo, hi = p.min(axis=0), p.max(axis=0)
    pad = CROP_MARGIN * (hi - lo).max()
    h, w = shape[:2]
    return (
        max(lo[0] - pad, -0.5),
        min(hi[0] + pad, w - 0.5),
        max(lo[1] - pad, -0.5),
        min(hi[1] + pad, h - 0.5),
    )


def base_faces(faces: np.ndarray) -> np.ndarray | None:
    """The base (low-resolution) faces of a template subdivided 1-to-4, or None if not one.

    ``scan2morph.template.subdivide`` turns faces ``(a, b, c)`` into four blocks of F faces,
    ``(a, ab, ca)``, ``(ab, b, bc)``, ``(ca, bc, c)``, ``(ab, bc, ca)``; the structure is checked
    in full before the base is read off, and undone as often as it holds.

    Parameters
    ----------
    faces : (F, 3) int

    Returns
    -------
    (F / 4**levels, 3) int64, or None when ``faces`` is not a subdivided mesh.
    """
    faces = np.asarray(faces, dtype=np.int64)
    coarse = None
    while len(faces) % 4 == 0 and len(faces):
        n = len(faces) // 4
        q1, q2, q3, q4 = faces[:n], faces[n : 2 * n], faces[2 * n : 3 * n], faces[3 * n :]
        ab, ca, bc = q1[:, 1], q1[:, 2], q2[:, 2]
        if not (
            np.array_equal(q2[:, 0], ab)
            and np.array_equal(q3[:, :2], np.column_stack([ca, bc]))
            and np.array_equal(q4, np.column_stack([ab, bc, ca]))
        ):
            break
        faces = coarse = np.column_stack([q1[:, 0], q2[:, 1], q3[:, 2]])
    return coarse


def fig_landmarks(store: Mapping[str, np.ndarray]) -> Figure:
    """Color images with landmarks and with the fitted (warped) template (Fig. 1b, 2, 4).

    One row per take: the neutral and the viseme with the largest motion (else an expression).
    Columns: the 68 landmarks (clicked red, detected coloured by confidence); the warped template at the base (low) resolution when the store's
    mesh is a subdivision of it; the warped template as stored (high resolution), invalid vertices
    (no range data under them) marked with red crosses.
    """
    faces = template_faces(store, "the landmark figure")
    coarse = base_faces(faces)
    meshes = ([("low resolution", coarse)] if coarse is not None else []) + [
        ("high resolution" if coarse is not None else "fitted template", faces)
    ]
    neutral = neutral_take(store)
    takes = [neutral] + [t for t in [example_take(store)] if t is not None]
    ncols = 1 + len(meshes)
    fig, axes = subplots(
        len(takes),
        ncols,
        figsize=(2.6 * ncols, 3.3 * len(takes)),
        squeeze=False,
    )
    dots = []  # the detected landmarks' scatters (None for a clicked take)
    for row, take in enumerate(takes):
        what = f"the landmark figure of take {take}"
        color = need(store, paths.range_image(take, "color"), what)
        marks = need(store, paths.landmarks(take), what).astype(float)
        pts = need(store, paths.mesh(take, "points2d"), what).astype(float)
        valid = need(store, paths.mesh(take, "valid"), what).astype(bool)
        if pts.shape != (len(valid), 2) or marks.shape != (68, 2):
            raise InputError(
                source_of(store),
                f"{paths.take(take)}: points2d, valid or landmarks have the wrong shape",
            )
        x0, x1, y0, y1 = _crop_box(np.vstack([pts, marks]), color.shape)
        shown = opaque_rgba(color)
        for ax in axes[row]:
            ax.imshow(shown, interpolation="bilinear")
            ax.set_xlim(x0, x1)
            ax.set_ylim(y1, y0)
            ax.set_xticks([])
            ax.set_yticks([])
        dots.append(_landmark_dots(axes[row, 0], marks, store.get(paths.landmark_confidence(take))))
        source = landmark_source(store, take)
        axes[row, 0].set_title(f"{take}: 68 landmarks, {source}", fontsize=8)
        axes[row, 0].set_ylabel(image_name(store, take), fontsize=8)
        for ax, (label, tri) in zip(axes[row, 1:], meshes, strict=True):
            tri = _valid_faces(pts, tri)
            lw = 0.35 if len(tri) < 1500 else 0.2
            ax.triplot(Triangulation(pts[:, 0], pts[:, 1], tri), color="cyan", lw=lw, alpha=0.9)
            ax.set_title(f"{take}: {label} ({len(tri)} faces)", fontsize=8)
        bad = ~valid & np.all(np.isfinite(pts), axis=1)
        axes[row, -1].scatter(pts[bad, 0], pts[bad, 1], s=6, marker="x", c="red", linewidths=0.6)
        axes[row, -1].set_xlabel(f"{valid.sum()} of {len(valid)} vertices valid", fontsize=7)
    _confidence_bar(fig, axes[:, 0], dots)
    # named per modality: a stereo take's left image, a mesh scan's render (not "color image")
    shown = list(dict.fromkeys(image_name(store, t) for t in takes))
    fig.suptitle(f"Template fitted to the {' and the '.join(shown)}", fontsize=10)
    return fig


def fig_model(store: Mapping[str, np.ndarray]) -> Figure:
    """The neutral 3D model shaded, textured and as wireframe (Fig. 3)."""
    faces = template_faces(store, "the model figure")
    take = neutral_take(store)
    what = f"the model figure of take {take}"
    vertices = mesh(store, paths.mesh(take, "vertices"), what)
    uv = need(store, paths.mesh(take, "uv"), what)
    color = need(store, paths.range_image(take, "color"), what)
    view = face_view(
        vertices, faces, need(store, paths.template("vertices2d"), what), source=source_of(store)
    )
    panels = [
        Panel(render_view(TexturedMesh(vertices, faces), view), "(a) shaded"),
        Panel(render_view(TexturedMesh(vertices, faces, uv, color), view), "(b) textured"),
        Panel(
            render_view(TexturedMesh(vertices, faces), view, rgb=WIRE_RGB, wireframe=True),
            "(c) wireframe",
        ),
    ]
    named = "" if take == "neutral" else f" ({take})"  # not "neutral take (neutral)"
    return panel_figure(
        panels, ncols=3, title=f"3D face model of the neutral take{named}, scanner frame"
    )


def _text(store: Mapping, key: str, default: str) -> str:
    value = store[key] if key in store else default
    value = value.item() if isinstance(value, np.ndarray) else value
    return value.decode() if isinstance(value, bytes) else str(value)


#: Characters of a 9 pt title (7 pt: a few more) that fit an inch of the figure.
TITLE_CHARS_PER_INCH = 13


def fig_takes(store: Mapping[str, np.ndarray]) -> Figure:
    """Every take's image with its 68 landmarks, as the fit saw them: a range or RGB-D take's
    colour image, a stereo take's left image, a mesh take's render through its virtual camera
    (grey shading for a geometry-only mesh). The neutral first, then the others by name."""
    neutral = neutral_take(store)
    takes = [neutral] + [t for t in groups(store, paths.TAKES, "mesh/vertices") if t != neutral]
    ncols = min(TAKES_PER_ROW, len(takes))
    nrows = -(-len(takes) // ncols)
    fig, axes = subplots(nrows, ncols, figsize=(2.3 * ncols, 2.7 * nrows), squeeze=False)
    for ax in axes.flat:
        axes_off(ax)
    dots = []  # the detected landmarks' scatters (None for a clicked take)
    modalities = set()
    for ax, take in zip(axes.flat, takes, strict=False):
        what = f"the takes figure of take {take}"
        color = need(store, paths.range_image(take, "color"), what)
        marks = need(store, paths.landmarks(take), what).astype(float)
        modality = _text(store, paths.camera(take, "modality"), "range")
        modalities.add(modality)
        shown = _text(store, paths.camera(take, "color_source"), "")
        x0, x1, y0, y1 = _crop_box(marks, color.shape)
        ax.imshow(opaque_rgba(color), interpolation="bilinear")
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        dots.append(_landmark_dots(ax, marks, store.get(paths.landmark_confidence(take))))
        source = landmark_source(store, take)
        doubtful = _text(store, paths.landmark_info(take, "doubtful"), "")
        note = ", ".join(n for n in (modality, shown, source, "DOUBTFUL" if doubtful else "") if n)
        # the take on one line, how it was seen on the next: side by side they overlapped
        title = f"{take}\n{fill(note, int(TITLE_CHARS_PER_INCH * 2.3))}"
        ax.set_title(title, fontsize=7, color="darkred" if doubtful else "black")
    _confidence_bar(fig, axes, dots)
    # the virtual camera named only where a mesh take is shown
    rendered = " (mesh takes: rendered by the virtual camera)" if "mesh" in modalities else ""
    text = (
        f"Each take's image and landmarks{rendered}; clicked points red, detected ones coloured "
        "by confidence (yellow high, purple low)"
    )
    # wrapped to the figure's width (one row of four takes cut it at both ends)
    fig.suptitle(fill(text, int(TITLE_CHARS_PER_INCH * 2.3 * ncols)), fontsize=9)
    return fig


def _landmark_dots(ax, marks: np.ndarray, confidence: np.ndarray | None):
    """Clicked points red; detected ones (finite ``confidence``) coloured by their confidence:
    the scatter of the detected ones (for a colour bar), None without any."""
    conf = np.full(len(marks), np.nan) if confidence is None else np.asarray(confidence, float)
    clicked = ~np.isfinite(conf)
    ax.scatter(*marks[clicked].T, s=5, c="red", edgecolors="none")
    if not (~clicked).any():
        return None
    return ax.scatter(
        *marks[~clicked].T,
        s=6,
        c=conf[~clicked],
        cmap="plasma",
        vmin=0.0,
        vmax=1.0,
        edgecolors="none",
    )


def _confidence_bar(fig: Figure, axes, dots: list) -> None:
    """The detected landmarks' confidence colour bar beside ``axes`` (an array of axes), when
    any panel shows detected points (``dots``: their scatters, None for a clicked take)."""
    shown = [d for d in dots if d is not None]
    if shown:
        fig.colorbar(shown[0], ax=list(np.ravel(axes)), shrink=0.4, label="landmark confidence")


#: Panels per row of :func:`fig_takes`: three (2.3 inches each at 150 dpi, 1035 px) fit the
#: report's 1200 px page at their own size; five (1725 px) were shrunk to two thirds there, their
#: 7 pt take titles to about 5 pt.
TAKES_PER_ROW = 3
#: Figure name -> function, in the order the report shows them.
FIGURES = {
    "template": fig_template,
    "takes": fig_takes,
    "landmarks": fig_landmarks,
    "model": fig_model,
}
