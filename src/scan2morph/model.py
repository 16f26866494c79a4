"""A subject's morphable face model, read back from its store: the Python API of the product.

>>> import scan2morph
>>> model = scan2morph.load_model("results/synth01/synth01.h5")
>>> face = model.blend({"car": 0.5})          # (V, 3) mm, Eq. 1 of Yano & Harada
>>> other = model.pca([1.0, -0.5])            # (V, 3) mm, Eq. 2 (alphas in units of sigma)
>>> model.faces.shape, model.warnings

Everything is in the neutral take's scanner frame, mm, as in the store; ``model.head_frame``
maps it to the glTF's head frame (metres, +Y up, +Z out of the face).

The glTF (and Blender's shape keys) hold the same PCA as additive morph targets: ``pca_mean`` and,
per component k, ``pca_k_pos`` and ``pca_k_neg``, each at weight 1 = +-3 sigma_k. A shape-key
value w on ``pca_k_pos`` is alpha_k = 3 w, on ``pca_k_neg`` alpha_k = -3 w; with ``pca_mean`` at 1
they give ``model.pca(alphas)``, and ``model.pca_weights(alphas)`` is the set of values to type in.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scan2morph.errors import InputError
from scan2morph.morph.blend import blend
from scan2morph.morph.pca import ALPHA_LIMIT
from scan2morph.morph.subject import pca_target_weights
from scan2morph.store import open_store, paths
from scan2morph.store.hdf5 import attr_value
from scan2morph.store.warnings import (
    Failure,
    Warning,
    read_failures,
    read_warnings,
    skipped_stages,
)


@dataclass(frozen=True)
class Model:
    """One subject's model.

    Attributes
    ----------
    subject : str
    neutral : (V, 3) float, mm
        The base model S_0 (the neutral mesh, invalid vertices filled from neighbours).
    faces : (F, 3) int
        Template faces, shared by every mesh of the subject.
    uv : (V, 2) float or None
        Texture coordinates of the neutral into its colour image (top-left origin).
    texture : (H, W, 3) uint8 or None
        The neutral's colour image.
    visemes : dict take -> (V, 3) mm
        Viseme models (neutral + masked, smoothed motion), in the neutral frame.
    labels : dict take -> label
        The label (``car``, ``smile``, ...) of every take.
    pca_mean, pca_components, pca_sigma : arrays or None
        (V, 3), (K, V, 3) unit-norm components, (K,) mm; None without visemes.
    sigma_convention : str or None
        ``sample`` (the coefficients' sample standard deviation) or ``paper`` (sqrt eigenvalue).
    frequencies_hz : (k,) float
        Frequencies of the modal basis, Hz: the natural ones (coordinates ``mass``) or each
        orthonormalised mode's Rayleigh-quotient frequency (coordinates ``vertex``, the default),
        which need not ascend.
    modes : (k, V, 3) float
        Mode shapes (translational part), orthonormal in the mass the coordinates use: the
        model's mass (``/modal/physics`` coordinates ``mass``) or, by default (preset ``skin``,
        coordinates ``vertex``), the total mass shared equally by the vertices.
    coordinates : dict take -> (k,) float
        Modal coordinates of each expression.
    head_frame : (4, 4) float or None
        Neutral frame (mm) -> glTF head frame (m).
    modal_preset : str or None
        The physics of the modal basis (``modal.preset``: ``skin``, ``skin_v1``,
        ``clamped_still``, ``paper``); None in a store written before format 1.4.
    failed : dict take -> Failure
        The takes left out of the subject (bad input or a quality gate at a per-take stage), with
        the stage that refused each and why.
    warnings : list of Warning
        What not to trust (misaligned takes left out, refused refits, ...).
    skipped : dict stage -> why
    provenance : dict
        The store's root attributes (format and software versions, config hash, checksums).
    """

    subject: str
    neutral: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None
    texture: np.ndarray | None
    visemes: dict[str, np.ndarray]
    labels: dict[str, str]
    pca_mean: np.ndarray | None
    pca_components: np.ndarray | None
    pca_sigma: np.ndarray | None
    sigma_convention: str | None
    frequencies_hz: np.ndarray
    modes: np.ndarray
    coordinates: dict[str, np.ndarray]
    head_frame: np.ndarray | None
    modal_preset: str | None = None
    failed: dict[str, Failure] = field(default_factory=dict)
    warnings: list[Warning] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    provenance: dict[str, object] = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line of what the model holds (the dataclass's own repr prints every array)."""
        k = 0 if self.pca_sigma is None else len(self.pca_sigma)
        parts = [
            f"{len(self.neutral)} vertices",
            f"{len(self.faces)} faces",
            f"visemes {sorted(self.visemes)}",
            f"{k} PCA components",
            f"{len(self.modes)} modes ({self.modal_preset or 'preset not recorded'})",
            f"expressions {sorted(self.coordinates)}",
        ]
        if self.failed:
            parts.append(f"left out {sorted(self.failed)}")
        if self.warnings:
            parts.append(f"{len(self.warnings)} warnings")
        return f"Model({self.subject!r}: " + ", ".join(parts) + ")"

    def blend(self, weights: Mapping[str, float]) -> np.ndarray:
        """A blend shape (Eq. 1): ``(1 - sum w) S_0 + sum_l w_l S_l``.

        Parameters
        ----------
        weights : mapping label or take -> weight
            Weights of viseme labels (``{"car": 0.5}``; repeated takes of a label are averaged)
            or of take ids; non-negative, summing to at most 1.

        Returns
        -------
        (V, 3) float, mm
        """
        shapes: dict[str, list[np.ndarray]] = {}
        for take, shape in self.visemes.items():
            shapes.setdefault(self.labels.get(take, take), []).append(shape)
        by_name = {label: np.mean(s, axis=0) for label, s in shapes.items()} | self.visemes
        return blend(self.neutral, by_name, dict(weights), source=f"{self.subject}/blend")

    def pca(self, alphas: Sequence[float], alpha_limit: float = ALPHA_LIMIT) -> np.ndarray:
        """A PCA synthesis (Eq. 2): ``mean + sum_k alpha_k sigma_k e_k``.

        Parameters
        ----------
        alphas : sequence of float
            One per leading component (at most K), each within ``[-alpha_limit, alpha_limit]``.

        Returns
        -------
        (V, 3) float, mm
        """
        if self.pca_mean is None:
            raise InputError(self.subject, "pca: the subject has no PCA (no viseme takes)")
        a = np.asarray(alphas, dtype=np.float64).ravel()
        k = len(self.pca_sigma)
        if a.size > k or not np.isfinite(a).all() or (np.abs(a) > alpha_limit).any():
            raise InputError(
                self.subject,
                f"pca: expected at most {k} finite alphas within +-{alpha_limit}, got {a.tolist()}",
            )
        weights = a * self.pca_sigma[: a.size]
        return self.pca_mean + np.tensordot(weights, self.pca_components[: a.size], axes=1)

    def pca_weights(
        self, alphas: Sequence[float], alpha_limit: float = ALPHA_LIMIT
    ) -> dict[str, float]:
        """The glTF morph-target weights (Blender shape-key values) that show ``pca(alphas)``.

        Parameters
        ----------
        alphas : sequence of float
            As for :meth:`pca`, in units of sigma_k.

        Returns
        -------
        dict target name -> weight
            ``pca_mean`` 1; ``pca_k_pos`` ``alpha_k / 3`` when ``alpha_k >= 0``, else
            ``pca_k_neg`` ``-alpha_k / 3`` (the other 0): every weight within 0..1 for alphas
            within +-3 (:data:`scan2morph.morph.subject.PCA_TARGET_SIGMAS`).
        """
        self.pca(alphas, alpha_limit)  # the same checks
        return pca_target_weights(alphas)

    def expression(self, coordinates: Sequence[float]) -> np.ndarray:
        """The neutral displaced by modal coordinates ``q`` (the first len(q) modes), mm."""
        q = np.asarray(coordinates, dtype=np.float64).ravel()
        if q.size > len(self.modes) or not np.isfinite(q).all():
            raise InputError(
                self.subject, f"expression: expected at most {len(self.modes)} finite coordinates"
            )
        return self.neutral + np.tensordot(q, self.modes[: q.size], axes=1)


def _get(h5, key):
    return h5[key][()] if key in h5 else None


def load_model(path: str | Path) -> Model:
    """Read a subject's model from ``results/{subject}/{subject}.h5``.

    Raises
    ------
    InputError
        Not a store, an unknown major format version (:func:`scan2morph.store.open_store`).
    """
    with open_store(path) as h5:
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in h5.attrs.items()}
        takes = h5.get(paths.TAKES, {})
        labels = {t: str(takes[t].attrs.get("label", t)) for t in takes}
        neutral = [t for t in takes if takes[t].attrs.get("kind") == "neutral"]
        visemes = paths.ids(_keys(h5, paths.VISEMES), paths.VISEMES, "model")
        expressions = paths.ids(_keys(h5, paths.EXPRESSIONS), paths.EXPRESSIONS, "coordinates")
        convention = _get(h5, paths.pca("sigma_convention"))
        return Model(
            subject=str(attrs.get("subject", Path(path).stem)),
            neutral=h5[paths.neutral("vertices")][()],
            faces=h5[paths.template("faces")][()],
            uv=_get(h5, paths.mesh(neutral[0], "uv")) if neutral else None,
            texture=_get(h5, paths.range_image(neutral[0], "color")) if neutral else None,
            visemes={t: h5[paths.viseme(t, "model")][()] for t in visemes},
            labels=labels,
            pca_mean=_get(h5, paths.pca("mean")),
            pca_components=_get(h5, paths.pca("components")),
            pca_sigma=_get(h5, paths.pca("sigma")),
            sigma_convention=None if convention is None else str(attr_value(convention)),
            frequencies_hz=h5[paths.modal("frequencies_hz")][()],
            modes=h5[paths.modal("modes")][()],
            coordinates={t: h5[paths.expression(t, "coordinates")][()] for t in expressions},
            head_frame=_get(h5, paths.neutral("head_frame")),
            modal_preset=_text(h5, paths.modal("preset")),
            failed=read_failures(h5),
            warnings=read_warnings(h5),
            skipped=skipped_stages(h5),
            provenance={k: attr_value(v) for k, v in attrs.items()},
        )


def _text(h5, key: str) -> str | None:
    """A text dataset, or None when the store has none."""
    value = _get(h5, key)
    if value is None:
        return None
    return value.decode() if isinstance(value, bytes) else str(value)


def _keys(h5, root: str) -> list[str]:
    if root not in h5:
        return []
    out = []
    h5[root].visititems(lambda name, obj: out.append(f"{root}/{name}"))
    return out
