"""Figures of the morphable models (Yano and Harada, Fig. 11-16, Tables 1-2)."""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from scan2morph.errors import InputError
from scan2morph.geometry import TexturedMesh
from scan2morph.render.source import (
    groups,
    mesh,
    need,
    neutral_take,
    neutral_view,
    source_of,
    template_faces,
)
from scan2morph.render.views import (
    Panel,
    frame_view,
    message_figure,
    panel_figure,
    render_view,
    subplots,
)
from scan2morph.store import paths

#: Eigen models shown (the paper shows the top five).
N_EIGEN = 5
#: Multiples of sigma (``/pca/sigma``) of the eigen-model columns (alpha limits of Eq. 2).
EIGEN_ALPHAS = (-3.0, 0.0, 3.0)
#: How each sigma convention (``/pca/sigma_convention``) is named in the figures.
SIGMA_TITLES = {
    "sample": "σ = sample std of the coefficients",
    "paper": "σ = √eigenvalue, as in the paper",
}
#: A gradual-series blend is named ``{label}_{percent}`` (config ``morph.blends``: ``car_30``).
_GRADUAL = re.compile(r"^(?P<label>[A-Za-z][A-Za-z0-9-]*)_(?P<percent>\d{1,3})$")
#: A mixed blend is named by ``{label}{percent}`` parts joined by ``_`` (``man60_eel30``).
_MIXED_PART = re.compile(r"^(?P<label>[A-Za-z][A-Za-z-]*)(?P<percent>\d{1,3})$")
#: Roots of the named blends and PCA blends.
_BLENDS = paths.BLENDS
_PCA_BLENDS = paths.PCA_BLENDS


def _render_shapes(
    store: Mapping, shapes: Mapping[str, np.ndarray], what: str
) -> dict[str, np.ndarray]:
    """Shaded renders of neutral-frame shapes at one scale (the neutral's view)."""
    faces = template_faces(store, what)
    view = frame_view(neutral_view(store, what), list(shapes.values()), faces)
    return {name: render_view(TexturedMesh(v, faces), view) for name, v in shapes.items()}


def blend_title(name: str) -> str:
    """A blend's weights spelled out from its name (``man60_eel30`` -> ``0.6 man + 0.3 eel + 0.1 base``);
    the name itself when it does not follow the convention."""
    parts = [_MIXED_PART.match(p) for p in name.split("_")]
    gradual = _GRADUAL.match(name)
    if gradual:
        parts = [_MIXED_PART.match(f"{gradual['label']}{gradual['percent']}")]
    if not all(parts):
        return name
    weights = [(int(m["percent"]) / 100.0, m["label"]) for m in parts]
    rest = 1.0 - sum(w for w, _ in weights)
    terms = [f"{w:g} {label}" for w, label in weights] + (
        [f"{rest:.2g} base"] if rest > 1e-9 else []
    )
    return " + ".join(terms)


def fig_gradual(store: Mapping[str, np.ndarray]) -> Figure:
    """Gradual deformation from the base model towards single visemes (Fig. 11)."""
    what = "the gradual-deformation figure"
    series: dict[str, list[tuple[int, str]]] = {}
    for name in groups(store, _BLENDS, "vertices"):
        m = _GRADUAL.match(name)
        if m:
            series.setdefault(m["label"], []).append((int(m["percent"]), name))
    if not series:
        return message_figure(
            "Gradual deformation", f"no blend named {{label}}_{{percent}} in {_BLENDS}"
        )
    ncols = max(len(s) for s in series.values())
    names = [name for label in series for _, name in sorted(series[label])]
    images = _render_shapes(store, {n: mesh(store, paths.blend(n), what) for n in names}, what)
    panels = []
    for label, items in series.items():
        row = [Panel(images[name], f"{label}, w = {pct / 100:g}") for pct, name in sorted(items)]
        panels += row + [Panel(None)] * (ncols - len(row))
    return panel_figure(
        panels,
        ncols=ncols,
        title="Gradual deformation of the base model towards each viseme (Eq. 1)",
    )


def fig_blends(store: Mapping[str, np.ndarray]) -> Figure:
    """Blends of several visemes (Fig. 12): every named blend that is not a gradual series."""
    what = "the blend figure"
    names = [n for n in groups(store, _BLENDS, "vertices") if not _GRADUAL.match(n)]
    if not names:
        return message_figure("Blends of visemes", f"no mixed blend in {_BLENDS}")
    images = _render_shapes(store, {n: mesh(store, paths.blend(n), what) for n in names}, what)
    panels = [Panel(images[n], blend_title(n)) for n in names]
    return panel_figure(panels, ncols=min(len(panels), 4), title="Blends of viseme models (Eq. 1)")


def fig_mean(store: Mapping[str, np.ndarray]) -> Figure:
    """The mean model of the PCA (Fig. 13), shaded and with the neutral's texture."""
    what = "the mean-model figure"
    faces = template_faces(store, what)
    mean = mesh(store, paths.pca("mean"), what)
    neutral = neutral_take(store)
    uv = need(store, paths.mesh(neutral, "uv"), what)
    color = need(store, paths.range_image(neutral, "color"), what)
    view = frame_view(neutral_view(store, what), [mean], faces)
    panels = [
        Panel(render_view(TexturedMesh(mean, faces), view), "shaded"),
        Panel(render_view(TexturedMesh(mean, faces, uv, color), view), "textured (neutral image)"),
    ]
    n = len(need(store, paths.pca("takes"), what))
    return panel_figure(panels, ncols=2, title=f"Average face model of the {n} models of the PCA")


def pca_sigma(store: Mapping, what: str) -> tuple[np.ndarray, str]:
    """``/pca/sigma`` and its convention; a store without them (older than sigma conventions)
    gives the paper's sqrt(eigenvalue)."""
    if paths.pca("sigma") in store:
        sigma = need(store, paths.pca("sigma"), what).astype(float)
        return sigma, str(need(store, paths.pca("sigma_convention"), what))
    return np.sqrt(
        np.maximum(need(store, paths.pca("eigenvalues"), what).astype(float), 0)
    ), "paper"


def _pca(store: Mapping, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    mean = mesh(store, paths.pca("mean"), what)
    comps = need(store, paths.pca("components"), what).astype(float)
    eig = need(store, paths.pca("eigenvalues"), what).astype(float)
    if comps.ndim != 3 or comps.shape[1:] != mean.shape or len(eig) != len(comps):
        raise InputError(
            source_of(store),
            f"{paths.PCA}: components {comps.shape} and eigenvalues {eig.shape} do not match the mean {mean.shape}",
        )
    return mean, comps, eig


def fig_eigen(store: Mapping[str, np.ndarray]) -> Figure:
    """The first eigen models at mean - 3 sigma, mean and mean + 3 sigma (Fig. 14); sigma is
    ``/pca/sigma`` (by default the sample std of the coefficients), named in the title."""
    what = "the eigen-model figure"
    mean, comps, eig = _pca(store, what)
    sigmas, convention = pca_sigma(store, what)
    n = min(N_EIGEN, int(np.sum(eig > 1e-12 * max(eig.max(initial=0.0), 1e-300))))
    if n == 0:
        return message_figure(
            "Eigen face models", "the PCA has no component with a positive eigenvalue"
        )
    # the mean column is one shape (mean + 0 sigma): rendered once for every row
    shapes = {
        (i, a) if a else "mean": mean + a * sigmas[i] * comps[i]
        for i in range(n)
        for a in EIGEN_ALPHAS
    }
    images = _render_shapes(store, shapes, what)
    panels = []
    for i in range(n):
        for a in EIGEN_ALPHAS:
            label = "mean" if a == 0 else f"mean {'+' if a > 0 else '−'} {abs(a):g}σ"
            panels.append(Panel(images[(i, a) if a else "mean"], f"PC{i + 1}: {label}"))
    # sigma is the length of the whole (3V,) vector: a vertex moves by its RMS, sigma / sqrt(V);
    # on two lines, so that the upright label fits its row (on one it ran into the next rows')
    rows = [
        f"PC{i + 1}: σ = {sigmas[i]:.1f} mm\n{sigmas[i] / np.sqrt(len(mean)):.2f} mm RMS a vertex"
        for i in range(n)
    ]
    return panel_figure(
        panels,
        ncols=len(EIGEN_ALPHAS),
        title=f"Principal eigen face models ({SIGMA_TITLES.get(convention, convention)})",
        row_labels=rows,
    )


def pca_alphas(store: Mapping[str, np.ndarray], shape: np.ndarray) -> np.ndarray:
    """The alphas of Eq. 2 that give ``shape``: ``alpha_i = e_i . (S - mean) / sigma_i``
    (``/pca/sigma``, in the store's sigma convention).

    Components with a zero eigenvalue are left out. Returns (K',) float.
    """
    mean, comps, eig = _pca(store, "PCA alphas")
    sigma, _ = pca_sigma(store, "PCA alphas")
    keep = eig > 1e-12 * max(eig.max(initial=0.0), 1e-300)
    proj = comps[keep].reshape(keep.sum(), -1) @ (np.asarray(shape, float) - mean).ravel()
    return proj / sigma[keep]


def fig_pca_blends(store: Mapping[str, np.ndarray]) -> Figure:
    """Models synthesised from the PCA (Eq. 2, Fig. 16), titled with their alphas."""
    what = "the PCA blend figure"
    names = groups(store, _PCA_BLENDS, "vertices")
    if not names:
        return message_figure("PCA blends", f"no model in {_PCA_BLENDS}")
    shapes = {n: mesh(store, paths.pca_blend(n), what) for n in names}
    images = _render_shapes(store, shapes, what)
    panels = []
    for n in names:
        alpha = pca_alphas(store, shapes[n])
        last = int(np.flatnonzero(np.abs(alpha) > 1e-6).max(initial=-1)) + 1
        text = ", ".join(f"{a:.2f}" for a in np.round(alpha[: max(last, 1)], 2) + 0.0)
        panels.append(Panel(images[n], f"{n}\nα = ({text})"))
    return panel_figure(
        panels, ncols=min(len(panels), 4), title="Face models synthesised from the PCA (Eq. 2)"
    )


def _share(c: float) -> str:
    """A contribution ratio as a bar's label: three decimals, two significant digits below 0.01
    (a small component's 0.00045 read "0.000")."""
    return f"{c:.3f}" if c >= 0.01 or c == 0 else f"{c:.2g}"


def fig_contribution(store: Mapping[str, np.ndarray]) -> Figure:
    """Contribution rate (bars) and cumulative contribution rate (line) per component (Table 1)."""
    what = "the contribution-rate chart"
    cr = need(store, paths.pca("cr"), what).astype(float)
    ccr = need(store, paths.pca("ccr"), what).astype(float)
    eig = need(store, paths.pca("eigenvalues"), what).astype(float)
    k = np.arange(1, len(cr) + 1)
    fig, ax = subplots(figsize=(5.0, 3.4))
    ax.bar(k, cr, color="tab:blue", label="CR")
    ax.plot(k, ccr, "o-", color="tab:red", label="CCR")
    if len(k) <= 10:
        for x, c, e in zip(k, cr, eig, strict=True):
            inside = c > 0.25  # tall bars carry their label inside, clear of the CCR line
            ax.annotate(
                f"{_share(c)}\n({e:,.0f} mm²)" if e >= 100 else f"{_share(c)}\n({e:.3g} mm²)",
                (x, c),
                ha="center",
                va="top" if inside else "bottom",
                color="white" if inside else "black",
                fontsize=6,
                xytext=(0, -4 if inside else 2),
                textcoords="offset points",
            )
    ax.set_xticks(k)
    ax.set_xlabel("principal component")
    ax.set_ylabel("rate")
    ax.set_ylim(0, 1.12)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="center right", fontsize=8)
    ax.set_title(
        "PCA: contribution rate and cumulative contribution rate\n(bar labels: CR and eigenvalue)",
        fontsize=9,
    )
    return fig


def fig_coefficients(store: Mapping[str, np.ndarray]) -> Figure:
    """PCA coefficients of every model (Fig. 15, Table 2): grouped bars, one group per model."""
    what = "the coefficient chart"
    coef = need(store, paths.pca("coefficients"), what).astype(float)
    takes = [str(t) for t in need(store, paths.pca("takes"), what)]
    if coef.ndim != 2 or coef.shape[0] != len(takes):
        raise InputError(
            source_of(store),
            f"{paths.pca('coefficients')}: expected {len(takes)} rows ({paths.pca('takes')}), "
            f"got {coef.shape}",
        )
    k = min(N_EIGEN, coef.shape[1])
    width = 0.8 / max(k, 1)
    x = np.arange(len(takes))
    fig, ax = subplots(figsize=(max(5.0, 0.9 * len(takes) + 1.5), 3.4))
    for i in range(k):
        ax.bar(x + (i - (k - 1) / 2) * width, coef[:, i], width, label=f"w{i + 1}")
    ax.axhline(0, color="0.3", lw=0.6)
    ax.set_xticks(x, [f"{t} (base)" if j == 0 else t for j, t in enumerate(takes)], fontsize=8)
    ax.set_ylabel("coefficient (mm)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncol=k, loc="upper center", bbox_to_anchor=(0.5, -0.12), frameon=False)
    ax.set_title("PCA coefficients of each model", fontsize=9)
    return fig


#: Figure name -> function, in the order the report shows them.
def _needs_model(name: str, func):
    """``func``, or for a subject without a morphable model (no viseme takes: the morph stage
    skipped PCA and blends) a figure that says so."""

    def draw(store: Mapping[str, np.ndarray]) -> Figure:
        if paths.pca("mean") in store:
            return func(store)
        why = "no viseme takes: no blend shapes or PCA for this subject"
        return message_figure(name.replace("_", " ").capitalize(), why)

    return draw


FIGURES = {
    name: _needs_model(name, func)
    for name, func in {
        "gradual": fig_gradual,
        "blends": fig_blends,
        "mean": fig_mean,
        "eigen": fig_eigen,
        "pca_blends": fig_pca_blends,
        "contribution": fig_contribution,
        "coefficients": fig_coefficients,
    }.items()
}
