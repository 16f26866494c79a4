"""Figures of the modal analysis of expressions (modal-analysis paper, Fig. 5-8)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from scan2morph.errors import InputError
from scan2morph.geometry import TexturedMesh
from scan2morph.render.charts import bars
from scan2morph.render.source import (
    expression_takes,
    groups,
    mesh,
    need,
    neutral_view,
    source_of,
    template_faces,
)
from scan2morph.render.views import (
    ColorScale,
    Panel,
    frame_view,
    message_figure,
    panel_figure,
    render_view,
    subplots,
)
from scan2morph.store import paths
from scan2morph.store.modal_physics import vertex_coordinates

#: Modes shown on the neutral (the paper's Fig. 5 shows a few of the lowest).
N_MODES = 6
#: Units of a modal coordinate q = Q^T M v: v in mm, M in tonnes, Q mass-orthonormal (t^-1/2).
Q_UNITS = "mm·t$^{1/2}$"
#: Root of the per-label coordinate statistics.
_STATISTICS = paths.MODAL_STATISTICS


def _modes(store: Mapping, what: str) -> np.ndarray:
    modes = need(store, paths.modal("modes"), what).astype(float)
    v = len(need(store, paths.template("vertices2d"), what))
    if modes.ndim != 3 or modes.shape[1:] != (v, 3):
        raise InputError(
            source_of(store),
            f"{paths.modal('modes')}: expected shape (k, {v}, 3), got {modes.shape}",
        )
    return modes


def _field_scale(fields: list[np.ndarray], label: str) -> ColorScale:
    """0 to the 99th percentile of the magnitudes of several fields (one scale for all panels;
    the colour bar's arrow: the top 1% take its top colour)."""
    mags = np.concatenate([np.linalg.norm(f, axis=1) for f in fields])
    mags = mags[np.isfinite(mags)]
    vmax = float(np.percentile(mags, 99)) if mags.size else 1.0
    return ColorScale.clipped(0.0, max(vmax, 1e-6), label, mags)


def fig_modes(store: Mapping[str, np.ndarray]) -> Figure:
    """The lowest modes on the neutral, colour = displacement magnitude (Fig. 5): the natural
    modes, or with vertex coordinates (:func:`vertex_coordinates`) the stored basis vectors,
    natural modes orthonormalised per vertex, with their Rayleigh-quotient frequencies; the
    title says which."""
    what = "the mode-shape figure"
    f = template_faces(store, what)
    base = mesh(store, paths.neutral("vertices"), what)
    modes = _modes(store, what)[:N_MODES]
    freq = need(store, paths.modal("frequencies_hz"), what).astype(float)
    view = neutral_view(store, what)
    scale = ColorScale(0.0, 1.0, "|mode displacement| / its maximum")
    panels = []
    for i, mode in enumerate(modes):
        mag = np.linalg.norm(mode, axis=1)
        peak = np.nanmax(mag) if np.isfinite(mag).any() else 0.0
        rgb = scale.rgb(mag / peak if peak > 0 else mag)
        hz = f", {freq[i]:.1f} Hz" if i < len(freq) else ""
        panels.append(Panel(render_view(TexturedMesh(base, f), view, rgb=rgb), f"mode {i + 1}{hz}"))
    title = "Natural mode shapes of the neutral face"
    if vertex_coordinates(store):
        # one line (the grid leaves one line of title): the caption says the rest
        title = "Modes of the neutral face (orthonormalised per vertex; Hz: Rayleigh quotients)"
    return panel_figure(panels, ncols=min(3, len(panels)), title=title, scale=scale)


def _displacements(store: Mapping, what: str) -> dict[str, np.ndarray]:
    return {
        t: mesh(store, paths.expression(t, "displacement"), what) for t in expression_takes(store)
    }


def fig_expressions(store: Mapping[str, np.ndarray]) -> Figure:
    """Each expression's displacement field as colour on the neutral (Fig. 6)."""
    what = "the expression-field figure"
    fields = _displacements(store, what)
    if not fields:
        return message_figure("Expression displacement fields", "the store has no expression takes")
    f = template_faces(store, what)
    base = mesh(store, paths.neutral("vertices"), what)
    view = neutral_view(store, what)
    scale = _field_scale(list(fields.values()), "displacement magnitude (mm)")
    panels = [
        Panel(
            render_view(TexturedMesh(base, f), view, rgb=scale.rgb(np.linalg.norm(d, axis=1))), take
        )
        for take, d in fields.items()
    ]
    return panel_figure(
        panels,
        ncols=min(len(panels), 4),
        title="Expression displacement fields on the neutral face",
        scale=scale,
    )


def _bar_grid(n: int) -> tuple[Figure, np.ndarray]:
    """One bar chart per row, on shared axes so that rows compare."""
    fig, axes = subplots(
        n,
        1,
        figsize=(6.4, 1.5 * n + 0.8),
        sharex=True,
        sharey=True,
        squeeze=False,
    )
    return fig, axes[:, 0]


def fig_coordinates(store: Mapping[str, np.ndarray]) -> Figure:
    """Modal coordinates of each expression against mode number (Fig. 7)."""
    what = "the coordinate chart"
    takes = expression_takes(store)
    if not takes:
        return message_figure("Expression coordinates", "the store has no expression takes")
    fig, axes = _bar_grid(len(takes))
    for ax, take in zip(axes, takes, strict=True):
        q = need(store, paths.expression(take, "coordinates"), what).astype(float)
        bars(ax, np.arange(1, len(q) + 1), q, width=0.8, color="tab:blue")
        ax.axhline(0, color="0.3", lw=0.5)
        ax.set_ylabel(f"q ({Q_UNITS})", fontsize=7)
        ax.set_title(take, fontsize=8, loc="left")
        ax.grid(axis="y", alpha=0.3)
    axes[-1].set_xlabel("mode number")
    fig.suptitle("Expression coordinates in the natural modal basis", fontsize=10)
    return fig


def fig_reconstruction(store: Mapping[str, np.ndarray]) -> Figure:
    """Each expression rebuilt from its first K modes: the share of its RMS left against K
    (solid; dashed: the part along the neutral's normals), where the store has the expression's
    displacement; else the RMS error in mm."""
    what = "the reconstruction chart"
    takes = expression_takes(store)
    if not takes:
        return message_figure("Reconstruction error", "the store has no expression takes")
    ks = need(store, paths.modal("reconstruction_k"), what).astype(int)
    fig, ax = subplots(figsize=(5.0, 3.4))
    relative = all(paths.expression(t, "displacement") in store for t in takes)
    dashed = False
    for i, take in enumerate(takes):
        key = paths.expression(take, "reconstruction_rms_mm")
        rms = need(store, key, what).astype(float)
        if rms.shape != ks.shape:
            raise InputError(source_of(store), f"{key}: expected shape {ks.shape}, got {rms.shape}")
        scale = 1.0
        if relative:
            d = np.asarray(store[paths.expression(take, "displacement")], dtype=float)
            scale = float(np.sqrt(np.nanmean(np.sum(d**2, axis=1))))
        colour = f"C{i % 10}"
        ax.plot(ks, rms / scale, "o-", ms=3, color=colour, label=take)
        normal = paths.expression(take, "reconstruction_normal_rms_mm")
        if normal in store and np.shape(store[normal]) == ks.shape:
            ax.plot(ks, np.asarray(store[normal], dtype=float) / scale, "--", lw=0.8, color=colour)
            dashed = True
    handles, labels = ax.get_legend_handles_labels()
    if dashed:  # the dashed lines, once, in the legend: without it they were unexplained
        handles.append(Line2D([], [], ls="--", lw=0.8, color="0.3"))
        labels.append("dashed: part along the normals")
    ax.set_xscale("log")
    ax.set_xlabel("number of modes K")
    ax.set_ylabel("share of the expression's RMS left" if relative else "RMS error (mm)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3, which="both")
    ax.legend(handles, labels, fontsize=7)
    preset = paths.modal("preset")
    physics = f" (preset {store[preset]})" if preset in store else ""
    ax.set_title(f"Expressions rebuilt from their first K modes{physics}", fontsize=9)
    return fig


def fig_statistics(store: Mapping[str, np.ndarray]) -> Figure:
    """Mean and standard deviation of the coordinates over the takes of each label."""
    what = "the statistics chart"
    labels = groups(store, _STATISTICS, "mean")
    if not labels:
        return message_figure("Coordinate statistics", f"no expression label in {_STATISTICS}")
    fig, axes = _bar_grid(len(labels))
    for ax, label in zip(axes, labels, strict=True):
        mean = need(store, paths.modal_statistics(label, "mean"), what).astype(float)
        std = need(store, paths.modal_statistics(label, "std"), what).astype(float)
        key = paths.modal_statistics(label, "takes")
        n = len(np.atleast_1d(store[key])) if key in store else None
        x = np.arange(1, len(mean) + 1)
        err = np.where(np.isfinite(std), std, 0.0)
        bars(ax, x, mean, width=0.8, color="tab:green")
        ax.errorbar(x, mean, yerr=err, fmt="none", ecolor="k", lw=0.6, capsize=1.2)
        ax.axhline(0, color="0.3", lw=0.5)
        ax.set_ylabel(f"q ({Q_UNITS})", fontsize=7)
        single = " (one take: no std)" if not np.isfinite(std).any() else ""
        ax.set_title(
            f"{label}: mean ± std over {n if n is not None else '?'} take{'' if n == 1 else 's'}"
            f"{single}",
            fontsize=8,
            loc="left",
        )
        ax.grid(axis="y", alpha=0.3)
    axes[-1].set_xlabel("mode number")
    fig.suptitle("Modal coordinates per expression label", fontsize=10)
    return fig


def fig_synthesis(store: Mapping[str, np.ndarray]) -> Figure:
    """Each expression measured and synthesised from its coordinates, and their difference (Fig. 8)."""
    what = "the synthesis figure"
    fields = _displacements(store, what)
    if not fields:
        return message_figure("Expression synthesis", "the store has no expression takes")
    f = template_faces(store, what)
    base = mesh(store, paths.neutral("vertices"), what)
    synth = {t: mesh(store, paths.expression(t, "synthesized"), what) for t in fields}
    shapes = [base + d for d in fields.values()] + [base + s for s in synth.values()]
    view = frame_view(neutral_view(store, what), shapes, f)
    scale = _field_scale(list(fields.values()), "displacement magnitude or difference (mm)")
    # the bar's arrow over every value shown (the synthesised fields and differences too)
    shown = [
        np.linalg.norm(v, axis=1) for t, d in fields.items() for v in (d, synth[t], synth[t] - d)
    ]
    scale = ColorScale.clipped(scale.vmin, scale.vmax, scale.label, np.concatenate(shown))
    panels = []
    for take, d in fields.items():
        s = synth[take]
        # the difference is small on the fields' scale (it looks blank): its RMS says how small
        diff = np.linalg.norm(s - d, axis=1)
        rms = float(np.sqrt(np.nanmean(diff**2))) if np.isfinite(diff).any() else float("nan")
        panels += [
            Panel(
                render_view(
                    TexturedMesh(base + d, f), view, rgb=scale.rgb(np.linalg.norm(d, axis=1))
                ),
                f"{take}: measured",
            ),
            Panel(
                render_view(
                    TexturedMesh(base + s, f), view, rgb=scale.rgb(np.linalg.norm(s, axis=1))
                ),
                f"{take}: synthesised",
            ),
            Panel(
                render_view(
                    TexturedMesh(base + s, f), view, rgb=scale.rgb(np.linalg.norm(s - d, axis=1))
                ),
                f"{take}: |synth. - meas.|\nRMS {rms:.2f} mm",
            ),
        ]
    return panel_figure(
        panels, ncols=3, title="Expressions synthesised from their modal coordinates", scale=scale
    )


#: Figure name -> function, in the order the report shows them.
FIGURES = {
    "modes": fig_modes,
    "expressions": fig_expressions,
    "coordinates": fig_coordinates,
    "reconstruction": fig_reconstruction,
    "statistics": fig_statistics,
    "synthesis": fig_synthesis,
}
