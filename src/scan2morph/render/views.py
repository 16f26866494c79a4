"""The drawing kit of the figures: a face's own camera view, colour maps on meshes, panel grids.

No axis direction is assumed. A face mesh carries its template coordinates (x right, y down in
the canonical 2D frame), so the affine map from template to 3D gives the face's own "up" (towards
the brows) and "right"; the front is the area-weighted normal (faces are counter-clockwise seen
from the scanner). Meshes in one frame share one :class:`View`, so they render at one scale.

Figures are built on matplotlib's Agg canvas without pyplot (see :func:`new_figure`).

pyrender writes vertex colours through a display gamma (a grey of 0.5 comes out as 0.73), so
colours are linearised here before rendering: a frontal surface then shows the colour map's own
colours, darkened only by the shading.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import NullLocator
from PIL import Image

from scan2morph.errors import InputError
from scan2morph.geometry import TexturedMesh
from scan2morph.render.scene import Framing, MeshLook, front_direction, render_mesh

#: Width and height of one rendered panel, pixels.
PANEL_PX = 360
#: Resolution of the saved figures (a panel is then PANEL_PX / DPI inches wide).
DPI = 150
#: Colour map of every scalar field drawn on a mesh: blue = low, red = high, as the papers. The
#: middle of "turbo", without its near-black ends, which would hide the shading of the surface.
FIELD_CMAP = ListedColormap(colormaps["turbo"](np.linspace(0.12, 0.88, 256)), name="turbo_mid")
#: Colour of vertices without a value (NaN), sRGB.
NAN_RGB = (0.55, 0.55, 0.55)
#: Display gamma that pyrender applies to vertex colours (measured: 0.5 -> 0.73, 0.1 -> 0.35).
_RENDER_GAMMA = 2.2


@dataclass(frozen=True)
class View:
    """Camera framing of a face: where up and front point, and what to fit in the image.

    Attributes
    ----------
    up : (3,) float
        Unit vector that points up in the image (chin to brows).
    front : (3,) float
        Unit vector from the face towards the camera.
    center : (3,) float, mm
        Point at the image centre.
    radius : float, mm
        Radius of the sphere about ``center`` that the image shows.
    """

    up: np.ndarray
    front: np.ndarray
    center: np.ndarray
    radius: float


@dataclass(frozen=True)
class ColorScale:
    """A colour map with its limits and the colour bar's label (with units).

    ``extend`` is the colour bar's (matplotlib's ``"neither"``, ``"min"``, ``"max"``,
    ``"both"``): ``"max"`` when the data go beyond ``vmax`` (a scale cut at a percentile), so
    that the bar's arrow says the top colour means "this much or more" (see :meth:`clipped`).
    """

    vmin: float
    vmax: float
    label: str
    cmap: str | Colormap = field(default_factory=lambda: FIELD_CMAP)
    extend: str = "neither"

    @classmethod
    def clipped(cls, vmin: float, vmax: float, label: str, values: np.ndarray) -> ColorScale:
        """A scale from ``vmin`` to ``vmax`` whose colour bar shows an arrow at the ends the
        finite ``values`` pass (the colours there are clipped to the end colour)."""
        v = np.asarray(values, dtype=np.float64)
        v = v[np.isfinite(v)]
        over = bool(v.size) and float(v.max()) > vmax
        under = bool(v.size) and float(v.min()) < vmin
        extend = {(False, False): "neither", (True, False): "max", (False, True): "min"}.get(
            (over, under), "both"
        )
        return cls(vmin, vmax, label, extend=extend)

    @property
    def colormap(self) -> Colormap:
        return colormaps[self.cmap] if isinstance(self.cmap, str) else self.cmap

    def rgb(self, values: np.ndarray) -> np.ndarray:
        """(V,) values to (V, 3) sRGB in [0, 1]; NaN gets :data:`NAN_RGB`."""
        values = np.asarray(values, dtype=np.float64)
        span = self.vmax - self.vmin if self.vmax > self.vmin else 1.0
        t = np.clip((values - self.vmin) / span, 0.0, 1.0)
        rgb = self.colormap(np.nan_to_num(t))[:, :3]
        rgb[~np.isfinite(values)] = NAN_RGB
        return rgb

    def mappable(self) -> ScalarMappable:
        return ScalarMappable(norm=Normalize(self.vmin, self.vmax), cmap=self.colormap)


def _finite_rows(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Vertices used by a face whose three corners are finite, as a (V,) mask."""
    keep = np.all(np.isfinite(vertices[faces]), axis=(1, 2))
    used = np.zeros(len(vertices), dtype=bool)
    used[faces[keep].ravel()] = True
    return used


def _check_mesh(vertices, faces, source: str) -> tuple[np.ndarray, np.ndarray]:
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise InputError(source, f"vertices: expected shape (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.size == 0:
        raise InputError(source, f"faces: expected shape (F, 3) with F > 0, got {faces.shape}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(source, f"faces: indices must lie in 0..{len(vertices) - 1}")
    return vertices, faces


def frame_view(view: View, meshes: Sequence[np.ndarray], faces: np.ndarray) -> View:
    """The same directions, re-centred and re-sized to show every mesh of ``meshes`` whole.

    The centre is the middle of the meshes' bounding box in the view's own axes (right, up,
    front), so the face sits in the middle of the image whatever its proportions.
    """
    pts = np.concatenate([m[_finite_rows(m, faces)] for m in meshes])
    if len(pts) == 0:
        raise InputError("render", "nothing to frame: no face has three finite vertices")
    right = np.cross(view.up, view.front)
    basis = np.stack([right, view.up, view.front])
    local = pts @ basis.T
    mid = 0.5 * (local.min(axis=0) + local.max(axis=0))
    center = mid @ basis
    radius = float(np.linalg.norm(pts - center, axis=1).max())
    return replace(view, center=center, radius=radius)


def face_view(
    vertices: np.ndarray, faces: np.ndarray, vertices2d: np.ndarray, source: str = "render"
) -> View:
    """A face's own frontal, upright view.

    Parameters
    ----------
    vertices : (V, 3) float, mm, NaN where invalid
        The face mesh, in any right-handed frame.
    faces : (F, 3) int
        Counter-clockwise seen from the front.
    vertices2d : (V, 2) float
        The template's canonical coordinates of the same vertices (x right, y down).
    source : str
        Label for error messages.

    Returns
    -------
    View
        ``up`` is the 3D direction of the template's -y (least-squares affine map over the valid
        vertices), made perpendicular to ``front`` (the area-weighted normal).
    """
    vertices, faces = _check_mesh(vertices, faces, source)
    vertices2d = np.asarray(vertices2d, dtype=np.float64)
    if vertices2d.shape != (len(vertices), 2):
        raise InputError(
            source, f"vertices2d: expected shape ({len(vertices)}, 2), got {vertices2d.shape}"
        )
    ok = _finite_rows(vertices, faces) & np.all(np.isfinite(vertices2d), axis=1)
    if ok.sum() < 3:
        raise InputError(source, "vertices: fewer than 3 valid vertices, no view can be derived")
    design = np.column_stack([vertices2d[ok], np.ones(ok.sum())])
    coef = np.linalg.lstsq(design, vertices[ok], rcond=None)[0]
    front = front_direction(vertices, faces)
    up = -coef[1] - np.dot(-coef[1], front) * front
    norm = np.linalg.norm(up)
    if norm < 1e-12:
        raise InputError(
            source, "vertices: degenerate mesh (template y has no extent across the view)"
        )
    return frame_view(View(up / norm, front, np.zeros(3), 1.0), [vertices], faces)


def linear_rgb(rgb: np.ndarray) -> np.ndarray:
    """sRGB colours in [0, 1] as the linear values that render to them (see module notes)."""
    return np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0) ** _RENDER_GAMMA


def render_view(
    mesh: TexturedMesh,
    view: View,
    *,
    rgb: np.ndarray | None = None,
    wireframe: bool = False,
    yaw_deg: float = 0.0,
    size: int = PANEL_PX,
) -> np.ndarray:
    """Render a mesh in a view.

    Parameters
    ----------
    mesh : TexturedMesh
        Vertices (V, 3) mm (faces touching a NaN vertex are not drawn), faces (F, 3) and,
        optionally, a texture (H, W, 3) uint8 with its coordinates uv (V, 2) (v down; NaN
        coordinates are drawn at (0, 0)).
    view : View
    rgb : (V, 3) or (3,) float in [0, 1], optional
        Per-vertex (or one) sRGB colour (as a colour map gives them).
    wireframe : bool
    yaw_deg : float
        Turn about ``up`` (90 = profile).
    size : int
        Width and height, pixels.

    Returns
    -------
    (size, size, 3) uint8
    """
    vertices, faces = _check_mesh(mesh.vertices, mesh.faces, "render")
    colors = None if rgb is None else linear_rgb(np.broadcast_to(rgb, vertices.shape))
    uv = None if mesh.uv is None else np.nan_to_num(np.asarray(mesh.uv, dtype=np.float64))
    look = MeshLook(colors, mesh.texture, uv, wireframe)
    framing = Framing(view.up, view.front, yaw_deg, view.center, view.radius)
    return render_mesh(vertices, faces, look, framing, (size, size))


def new_figure(**kwargs) -> Figure:
    """A matplotlib Figure on an Agg canvas at :data:`DPI`, outside pyplot (no global state, no
    backend switch: the caller's backend is left alone, and nothing needs closing)."""
    fig = Figure(dpi=DPI, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def axes_off(ax) -> None:
    """Hide an axes' frame and ticks, with nothing left to measure: ``set_axis_off`` alone
    still has the tick locators place (and the layout measure) ticks nobody sees whenever the
    axes' title is placed."""
    ax.set_axis_off()
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(NullLocator())
        axis.set_minor_locator(NullLocator())


def subplots(nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float], **kwargs):
    """``pyplot.subplots`` on a :func:`new_figure` (constrained layout): (Figure, axes)."""
    fig = new_figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots(nrows, ncols, **kwargs)


@dataclass(frozen=True)
class Panel:
    """One image of a panel grid with its title (``image`` None leaves the cell empty)."""

    image: np.ndarray | None
    title: str = ""


#: Gap around each panel of a grid, inches.
GAP_IN = 0.04
#: Band of the figure title above a grid, of a legend row below it, of the row labels left of
#: it and of the colour bar (with its ticks and label) right of it, inches.
SUPTITLE_IN, LEGEND_ROW_IN, ROW_LABEL_IN, COLORBAR_IN = 0.28, 0.22, 0.4, 1.0
#: Band of each further line of a row label (9 pt lines), inches.
ROW_LABEL_LINE_IN = 9 * 1.2 / 72
#: The colour bar's gap to the grid and its largest width, inches.
COLORBAR_GAP_IN, COLORBAR_MAX_WIDTH_IN = 0.15, 0.25
#: Height of one line of an 8 pt panel title, and the title's gap to its image (matplotlib's
#: ``axes.titlepad``, 6 pt), inches.
TITLE_LINE_IN, TITLE_PAD_IN = 8 * 1.2 / 72, 6 / 72


def panel_figure(
    panels: Sequence[Panel],
    *,
    ncols: int,
    title: str,
    scale: ColorScale | None = None,
    legend: Sequence[tuple[tuple[float, float, float], str]] = (),
    row_labels: Sequence[str] = (),
    legend_ncol: int | None = None,
) -> Figure:
    """A grid of images with titles, an optional colour bar and legend.

    The grid is laid out here, not by a layout engine (see :func:`grid_layout`): every panel is
    its image resized once (PIL's Lanczos) to its box on the figure's pixel grid and put there
    pixel for pixel (a :class:`~matplotlib.image.FigureImage`, see :func:`figure_panels`), its
    title a text above it; no axes, so no ticks to measure.

    Parameters
    ----------
    panels : sequence of Panel
        Row by row; images (H, W, 3) uint8.
    ncols : int
    title : str
        Figure title (what is shown).
    scale : ColorScale, optional
        Adds a colour bar with its label (give units).
    legend : sequence of (sRGB, label)
        Colour swatches below the grid.
    row_labels : sequence of str
        Text left of each row, turned upright; lines split on ``"\n"`` (each line must fit
        the row's height: a long label is given on two lines).
    legend_ncol : int, optional
        Swatches per legend row (default: all in one row).
    """
    panels = crop_panels(panels)
    nrows = max(1, -(-len(panels) // ncols))
    shapes = [p.image.shape for p in panels if p.image is not None] or [(PANEL_PX, PANEL_PX)]
    panel_w, panel_h = shapes[0][1] / DPI, shapes[0][0] / DPI
    # room for the longest panel title, the figure title and one row of the legend (inches at
    # the font sizes below: about 0.06 per character of 8 pt, 0.075 of 10 pt)
    longest = max((len(line) for p in panels for line in p.title.split("\n")), default=0)
    panel_w = max(panel_w, 0.062 * longest + 0.1)
    ncol = legend_ncol or max(1, len(legend))
    legend_rows = -(-len(legend) // ncol)
    legend_w = max(
        (
            sum(0.065 * len(lab) + 0.5 for _, lab in legend[i : i + ncol])
            for i in range(0, len(legend), ncol)
        ),
        default=0.0,
    )
    label_lines = max((len(lab.split("\n")) for lab in row_labels), default=0)
    label_w = ROW_LABEL_IN + (label_lines - 1) * ROW_LABEL_LINE_IN if row_labels else 0.0
    width = max(
        ncols * panel_w + (1.0 if scale else 0.0) + label_w,
        0.075 * len(title) + 0.4,
        legend_w + 0.2,
    )
    height = nrows * (panel_h + 0.25) + 0.45 + 0.3 * legend_rows
    fig = new_figure(figsize=(width, height))
    layout = grid_layout(
        panels,
        (nrows, ncols),
        (width, height),
        margins=(
            label_w,
            COLORBAR_IN if scale else 0.0,
            LEGEND_ROW_IN * legend_rows,
        ),
    )
    for panel, rect in zip(panels, layout.rects, strict=True):
        _draw_panel(fig, panel, rect)
    for label, y in zip(row_labels, layout.row_centers, strict=False):
        fig.text(
            label_w / 2 / width,
            y,
            label,
            rotation=90,
            ha="center",
            va="center",
            fontsize=9,
            multialignment="center",
        )
    fig.suptitle(title, fontsize=10, y=1.0 - GAP_IN / height, va="top")
    if scale is not None:
        _colour_bar(fig, scale, layout, (width, height))
    if legend:
        handles = [Patch(facecolor=c, edgecolor="0.3", label=lab) for c, lab in legend]
        fig.legend(
            handles=handles,
            loc="lower center",
            bbox_to_anchor=(0.5, GAP_IN / height),
            ncol=ncol,
            fontsize=8,
            frameon=False,
        )
    return fig


def _colour_bar(fig: Figure, scale: ColorScale, layout, size: tuple[float, float]) -> None:
    """A panel grid's colour bar, right of the grid (``layout``: its :class:`GridLayout`;
    ``size``: the figure's width and height, inches), 0.8 of the grid's height."""
    width, height = size
    bottom, top = layout.grid_y
    span = 0.8 * (top - bottom)
    # matplotlib's colour bar is 1/20 as wide as long; here no wider than its band allows
    bar_w = min(span * height / 20, COLORBAR_MAX_WIDTH_IN) / width
    x = layout.grid_right + COLORBAR_GAP_IN / width
    cax = fig.add_axes((x, (top + bottom - span) / 2, bar_w, span))
    fig.colorbar(scale.mappable(), cax=cax, label=scale.label, extend=scale.extend)


@dataclass(frozen=True)
class GridLayout:
    """Where a panel grid's parts go: the panels in the figure's pixels, the rest in figure
    fractions (0-1), both from the bottom left.

    Attributes
    ----------
    rects : list of (left, bottom, width, height) int or None
        Each panel's image (None: an empty cell), pixels.
    row_centers : list of float
        The height of each row's images' middle, fraction.
    grid_y : (float, float)
        Bottom and top of the grid (titles included), fractions.
    grid_right : float
        Right edge of the grid, fraction.
    """

    rects: list[tuple[int, int, int, int] | None]
    row_centers: list[float]
    grid_y: tuple[float, float]
    grid_right: float


def grid_layout(
    panels: Sequence[Panel],
    shape: tuple[int, int],
    size: tuple[float, float],
    margins: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> GridLayout:
    """Lay out a grid of image panels with their titles on a figure of ``size`` inches.

    Each cell of the grid is alike: a title band as tall as the longest title (8 pt lines and
    the title's gap) above the largest image of the cell's width and height with the image's
    aspect, centred in the cell and snapped to the figure's pixels (:data:`DPI`). All images of
    one shape come out the same size.

    Parameters
    ----------
    panels : sequence of Panel
        Row by row, ``len(panels) <= rows * cols``.
    shape : (int, int)
        Rows and columns.
    size : (float, float)
        The figure's width and height, inches.
    margins : (float, float, float)
        Inches left of the grid (row labels), right of it (a colour bar) and below it (legend),
        besides the figure title's band (:data:`SUPTITLE_IN`) above it.

    Returns
    -------
    GridLayout
    """
    (nrows, ncols), (width, height) = shape, size
    left, right, below = margins
    x0, x1 = left + GAP_IN, width - right - GAP_IN
    y0, y1 = below + GAP_IN, height - SUPTITLE_IN
    cell_w, cell_h = (x1 - x0) / ncols, (y1 - y0) / nrows
    lines = max((len(p.title.split("\n")) for p in panels if p.title), default=0)
    band = TITLE_PAD_IN + lines * TITLE_LINE_IN if lines else 0.0
    box_w, box_h = (cell_w - GAP_IN) * DPI, (cell_h - band - GAP_IN) * DPI
    rects: list[tuple[int, int, int, int] | None] = []
    for i, panel in enumerate(panels):
        if panel.image is None:
            rects.append(None)
            continue
        h, w = panel.image.shape[:2]
        s = min(box_w / w, box_h / h)
        dw, dh = max(1, round(w * s)), max(1, round(h * s))
        row, col = divmod(i, ncols)
        cx = (x0 + (col + 0.5) * cell_w) * DPI
        cy = (y1 - row * cell_h - band - (cell_h - band) / 2) * DPI
        px, py = round(cx - dw / 2), round(cy - dh / 2)
        rects.append((px, py, dw, dh))
    centers = [(y1 - (r + 0.5) * cell_h - band / 2) / height for r in range(nrows)]
    return GridLayout(rects, centers, (y0 / height, y1 / height), x1 / width)


def _draw_panel(fig: Figure, panel: Panel, rect: tuple[int, int, int, int] | None) -> None:
    """One panel in its pixel rectangle: the image resized to it (Lanczos) and put on the figure
    pixel for pixel (a :class:`~matplotlib.image.FigureImage` labelled with the panel's title,
    see :func:`figure_panels`), its title above it as an axes title would be (8 pt, 6 pt above,
    on its baseline)."""
    if rect is None:
        return
    x, y, w, h = rect
    picture = Image.fromarray(panel.image)
    if picture.size != (w, h):
        picture = picture.resize((w, h), Image.Resampling.LANCZOS)
    fig.figimage(opaque_rgba(picture), xo=x, yo=y, origin="upper").set_label(panel.title)
    if panel.title:
        fig.text(
            (x + w / 2) / fig.bbox.width,
            (y + h + TITLE_PAD_IN * DPI) / fig.bbox.height,
            panel.title,
            fontsize=8,
            ha="center",
            va="baseline",
        )


def opaque_rgba(image: np.ndarray | Image.Image) -> np.ndarray:
    """An (H, W, 3) uint8 RGB image as (H, W, 4) RGBA, opaque, for matplotlib to draw: it makes an
    RGB image RGBA on every drawing, in Python (a 230 x 230 panel drawn in 3.7 ms as RGB, 1.5 ms
    as RGBA; a 640 x 480 colour image 14 ms a view). Other images come back unchanged.

    The drawn pixels are those of the RGB image, but for a few pixels one level apart where an
    RGB image is resampled (bilinear, not at 1:1): matplotlib rounds the two paths apart."""
    if isinstance(image, Image.Image):
        return np.asarray(image.convert("RGBA"))
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        return image
    return np.asarray(Image.fromarray(image).convert("RGBA"))


def figure_panels(fig: Figure) -> list[tuple[str, np.ndarray, tuple[slice, slice]]]:
    """The image panels of a :func:`panel_figure`: each one's title, its image as drawn ((h, w, 3)
    uint8) and the row and column slices of its pixels in :func:`figure_to_array`'s output."""
    height = int(fig.bbox.height)
    out = []
    for im in fig.images:
        image = np.asarray(im.get_array())[:, :, :3]
        h, w = image.shape[:2]
        rows = slice(height - int(im.oy) - h, height - int(im.oy))
        out.append((im.get_label(), image, (rows, slice(int(im.ox), int(im.ox) + w))))
    return out


def crop_panels(panels: Sequence[Panel], margin_px: int = 6) -> list[Panel]:
    """Crop every image to the union of the drawn (non-white) parts of all, so the panels keep
    one scale; all images must have one shape."""
    images = [p.image for p in panels if p.image is not None]
    if not images or len({im.shape for im in images}) != 1:
        return list(panels)
    # a pixel is drawn where any image has a channel below 250: the images' darkest value is
    # (one running minimum, instead of comparing and reducing a stack of all of them)
    darkest = np.array(images[0], copy=True)
    for image in images[1:]:
        np.minimum(darkest, image, out=darkest)
    drawn = darkest.min(axis=2) < 250
    if not drawn.any():
        return list(panels)
    rows, cols = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    r0, r1 = max(rows[0] - margin_px, 0), rows[-1] + margin_px + 1
    c0, c1 = max(cols[0] - margin_px, 0), cols[-1] + margin_px + 1
    return [Panel(None if p.image is None else p.image[r0:r1, c0:c1], p.title) for p in panels]


def message_figure(title: str, message: str) -> Figure:
    """A figure that says why there is nothing to show (e.g. a subject without expressions)."""
    fig = new_figure(figsize=(4.8, 1.6))
    fig.suptitle(title, fontsize=10)
    fig.text(0.5, 0.4, message, ha="center", va="center", fontsize=9, wrap=True)
    return fig


def figure_to_array(fig: Figure) -> np.ndarray:
    """Rasterise a figure at its own size and dpi: (H, W, 3) uint8."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[:, :, :3].copy()
