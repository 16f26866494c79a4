"""The figures of every stage, drawn from a subject's store, and the files they are saved to.

Each stage has a fixed list of figures (:data:`STAGE_FIGURES`, named in
:mod:`scan2morph.render.names`), so the workflow can name its outputs before the store exists: ``{out_dir}/{stage}_{name}.png``. Per-take panels are composed
into one figure per kind, whatever takes a subject has; a figure whose data a subject lacks (no
expression takes, no blends) says so instead of being left out.

Figure functions take a ``Mapping[str, ndarray]`` keyed by store path (see
:mod:`scan2morph.render.source`) and return a matplotlib :class:`~matplotlib.figure.Figure`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from PIL import Image
from PIL.PngImagePlugin import PngInfo

from scan2morph.errors import InputError, writing
from scan2morph.render import fit_figures, modal_figures, morph_figures, motion_figures
from scan2morph.render.names import FIGURE_NAMES, figure_names
from scan2morph.render.source import StoreMapping
from scan2morph.render.views import DPI

#: Stage -> figure name -> function(store) -> Figure.
STAGE_FIGURES: dict[str, dict[str, Callable[[Mapping[str, np.ndarray]], Figure]]] = {
    "fit": fit_figures.FIGURES,
    "motion": motion_figures.FIGURES,
    "morph": morph_figures.FIGURES,
    "modal": modal_figures.FIGURES,
}


#: zlib level of the PNG files. The files are RGB: the figures are opaque (white face colour),
#: so the alpha channel that ``savefig`` writes is 255 everywhere. Measured on a subject's 23
#: figures (synth01, best of 3): RGBA at level 3 (before) 0.89 CPU-s and 9.6 MB, RGB at level 1
#: 0.64 CPU-s and 8.7 MB: faster and smaller. The pixels are the same.
PNG_COMPRESS_LEVEL = 1


if {s: tuple(f) for s, f in STAGE_FIGURES.items()} != FIGURE_NAMES:
    raise RuntimeError("render.figures: the figure functions do not match render.names")


def stage_figures(store: Mapping[str, np.ndarray], stage: str) -> dict[str, Figure]:
    """Draw a stage's figures: ``{stage}_{name}`` -> Figure."""
    names = figure_names(stage)
    return {
        stem: func(store) for stem, func in zip(names, STAGE_FIGURES[stage].values(), strict=True)
    }


def save_png(fig: Figure, path: str | Path) -> None:
    """Write a figure as ``Figure.savefig(path, dpi=DPI, facecolor="white")`` does, pixel for
    pixel (its RGB: the alpha channel, 255 everywhere on the white face, is left out), at zlib
    level :data:`PNG_COMPRESS_LEVEL`, in one drawing instead of two.

    ``savefig`` draws a figure with a layout engine twice: once with its output switched off, so
    that the layout is computed, then for real, which computes it again. That first drawing
    still resamples every image and lays out every text; one drawing (its layout computed once)
    gives the same pixels."""
    fig.set_facecolor("white")
    fig.canvas.draw()
    write_png(np.asarray(fig.canvas.buffer_rgba()), path)


def write_png(pixels: np.ndarray, path: str | Path) -> None:
    """Write a drawn figure's (H, W, 3 or 4) uint8 pixels as an RGB PNG at :data:`DPI` and zlib
    level :data:`PNG_COMPRESS_LEVEL` (an alpha channel is dropped: the figures are opaque)."""
    rgb = np.ascontiguousarray(pixels[:, :, :3])
    info = PngInfo()
    info.add_text(
        "Software", f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/"
    )
    Image.fromarray(rgb).save(
        path, format="png", dpi=(DPI, DPI), compress_level=PNG_COMPRESS_LEVEL, pnginfo=info
    )


def write_stage_figures(
    store_path: str | Path,
    out_dir: str | Path,
    stage: str,
    expected: Sequence[str | Path] | None = None,
) -> list[Path]:
    """Render a stage's figures from a subject store to ``{out_dir}/{stage}_{name}.png``
    (:func:`write_figures` of the one stage)."""
    return write_figures(store_path, out_dir, [stage], expected)


def write_figures(
    store_path: str | Path,
    out_dir: str | Path,
    stages: Sequence[str] = tuple(FIGURE_NAMES),
    expected: Sequence[str | Path] | None = None,
    timings: dict[str, float] | None = None,
) -> list[Path]:
    """Render the figures of ``stages`` from a subject store to ``{out_dir}/{stage}_{name}.png``.

    The store is opened once and every dataset read once for all stages (a figure job draws
    every stage's figures: one interpreter, one store, one offscreen context). The PNG files are
    compressed at zlib level :data:`PNG_COMPRESS_LEVEL`.

    Parameters
    ----------
    store_path : str or Path
        ``results/{subject}/{subject}.h5``.
    out_dir : str or Path
        Folder of the PNG files (created).
    stages : sequence of {"fit", "motion", "morph", "modal"}
        Default: every stage, in :data:`~scan2morph.render.names.FIGURE_NAMES` order.
    expected : sequence of paths, optional
        The files the caller declared (a workflow rule's outputs); checked against
        :func:`figure_names` before anything is drawn.
    timings : dict, optional
        Filled with each stage's drawing and writing time, wall seconds (stage -> s).

    Returns
    -------
    list of Path
        The files written, stage by stage in :func:`figure_names` order.

    Raises
    ------
    InputError
        Unknown stage, unreadable store, a dataset a figure needs is missing or misshapen, or
        ``expected`` names other files than the stages draw.
    """
    out_dir = Path(out_dir)
    stems = {stage: figure_names(stage) for stage in stages}
    drawn = [out_dir / f"{stem}.png" for names in stems.values() for stem in names]
    if expected is not None:
        want = {Path(p).resolve() for p in expected}
        if want != {p.resolve() for p in drawn}:
            raise InputError(
                "workflow/rules/figures.smk",
                f"outputs {sorted(map(str, expected))} differ from the figures drawn "
                f"{sorted(map(str, drawn))}",
            )
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    with StoreMapping(store_path) as store:
        for stage, names in stems.items():
            start = time.perf_counter()
            for stem, func in zip(names, STAGE_FIGURES[stage].values(), strict=True):
                path = out_dir / f"{stem}.png"
                with writing(path):
                    save_png(func(store), path)
                written.append(path)
            if timings is not None:
                timings[stage] = time.perf_counter() - start
    return written
