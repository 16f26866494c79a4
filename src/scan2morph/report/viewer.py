"""The report's interactive 3D viewer: the subject's glTF in three.js, inside the one-file page.

The page must open from disk with no network, so everything is inline: the ``.glb`` as base64 in
a ``data-glb`` attribute, and one ``<script type="module">``: our own ``viewer/viewer.js`` with
three.js (the npm package ``three``, pinned in ``tools/viewer/package-lock.json``) and its
``GLTFLoader`` and ``OrbitControls`` add-ons, bundled into one module by esbuild (``make setup``
runs ``npm ci`` and ``npm run build`` in ``tools/viewer``, writing ``tools/viewer/dist/viewer.js``,
three.js's licence comment kept). Python only inlines that file; the page's
Content-Security-Policy allows exactly that script, by its SHA-256 hash (:func:`script_hash`).

The viewer shows the mesh under a camera on +Z looking down -Z (+Y up: the head frame of
:mod:`scan2morph.io.gltf`), orbit controls, texture on/off and wireframe, and three groups of
controls (the section's template is ``templates/viewer.html.j2``):

- semantic modes: one range slider per viseme target of the glTF and ``pca_mean`` (0..1), and
  one ``pca_k`` slider per PCA component in units of sigma_k (-3..3; sigma the sample standard
  deviation of the PCA coefficients unless the store says otherwise) that sets the weights of
  the component's two targets ``pca_k_pos`` and ``pca_k_neg`` (each +-3 sigma_k e_k at weight
  1: :func:`semantic_sliders`), drawn by three.js's morphing;
- modal modes: one slider per modal coordinate of the first ``n`` modes of the FEM basis, and one
  button per expression take that sets them to its coordinates and adds its remaining modes
  (so the face is the expression synthesised from all its coordinates, ``Model.expression``);
- fitted takes: a selector with previous/next buttons over the subject's takes, each shown as
  its aligned mesh (``/takes/{take}/align/vertices``), the faces on its invalid vertices hidden.

The user's ``.glb`` stays as it is (the morph targets a glTF viewer shows): the modes and the
takes reach the page as one extra binary block (:func:`viewer_data`: int16-quantized
displacements from the neutral in the glTF frame, one scale per vector; about 10 kB per vector
of 1,682 vertices) in the ``data-block`` attribute, described by the JSON of ``data-layout``,
which the page's script adds to the glTF's base positions on the CPU.
"""

from __future__ import annotations

import base64
import hashlib
import json
import re
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from scan2morph.errors import InputError
from scan2morph.io.gltf import _read_glb, read_glb_frame
from scan2morph.morph.subject import parse_pca_target
from scan2morph.store import paths
from scan2morph.store.warnings import skipped_stages

#: The npm package that pins three.js (``npm ci`` installs it into ``node_modules``).
VIEWER_PACKAGE = Path(__file__).resolve().parents[3] / "tools" / "viewer"
THREE_DIR = VIEWER_PACKAGE / "node_modules" / "three"
#: Our viewer module (imports ``three`` and ``three/addons/...`` like any three.js app).
VIEWER_JS = Path(__file__).with_name("viewer") / "viewer.js"
#: Range of the weight sliders: ``pca_k`` in standard deviations, everything else 0..1.
PCA_RANGE = (-3.0, 3.0)
WEIGHT_RANGE = (0.0, 1.0)
#: What a pca_k slider's unit is, per /pca/sigma_convention.
SIGMA_WORDS = {
    "sample": "sample standard deviations of the PCA coefficients",
    "paper": "square roots of the eigenvalues (the paper's sigma, no 1/M)",
}
#: A modal slider's half range moves the mode's largest vertex by this much, mm.
MODE_PEAK_MM = 10.0
#: The int16 that marks an invalid vertex in the viewer's binary block (:func:`quantize`).
INVALID = -32768
#: The CSP sources the viewer needs besides its script: GLTFLoader hands the embedded texture to
#: the browser as a ``blob:`` URL, which it fetches.
CSP_SOURCES = "img-src data: blob:; connect-src data: blob:"

#: The viewer bundled by esbuild (``make setup``): viewer.js with three.js, one ES module.
VIEWER_BUNDLE = VIEWER_PACKAGE / "dist" / "viewer.js"


def three_unavailable(
    three_dir: str | Path = THREE_DIR, bundle: str | Path = VIEWER_BUNDLE
) -> str | None:
    """Why the viewer cannot be shown (three.js or its bundle missing, or the bundle older than
    ``viewer.js``), or None when it can."""
    three_dir, bundle = Path(three_dir), Path(bundle)
    if not (three_dir / "package.json").is_file():
        return (
            f"three.js is not installed ({three_dir / 'package.json'} is missing): run `make setup` "
            "(npm ci in tools/viewer) and rebuild the report"
        )
    if not bundle.is_file():
        return (
            f"the viewer bundle {bundle} is missing: run `make setup` (esbuild bundles viewer.js "
            "with three.js) and rebuild the report"
        )
    if bundle.stat().st_mtime_ns < VIEWER_JS.stat().st_mtime_ns:
        return (
            f"the viewer bundle {bundle} is older than {VIEWER_JS}: run `make setup` to rebuild it"
        )
    return None


def three_version(three_dir: str | Path = THREE_DIR) -> str:
    """The installed three.js version (its ``package.json``)."""
    return json.loads((Path(three_dir) / "package.json").read_text())["version"]


def viewer_script(bundle: str | Path = VIEWER_BUNDLE) -> str:
    """The viewer's one module script, as esbuild bundled it.

    Raises
    ------
    InputError
        The bundle contains text that would end an inline ``<script>`` early (``</script`` or
        ``<!--``).
    """
    script = Path(bundle).read_text(encoding="utf-8")
    if re.search(r"</script|<!--", script, re.I):
        raise InputError(bundle, "bundle: the code contains '</script' or '<!--'")
    return script


def script_hash(script: str) -> str:
    """The CSP source that allows exactly this inline script: ``'sha256-...'``."""
    digest = hashlib.sha256(script.encode("utf-8")).digest()
    return f"'sha256-{base64.b64encode(digest).decode('ascii')}'"


def glb_target_names(path: str | Path) -> tuple[list[str], dict[str, str], dict[str, float]]:
    """The morph target names of a ``.glb`` (``mesh.extras.targetNames``), their notes
    (``targetNotes``) and the signed sigmas at weight 1 of the PCA targets (``targetSigmas``)."""
    gltf = _read_glb(Path(path))
    extras = (gltf.meshes[0].extras or {}) if gltf.meshes else {}
    names = [str(n) for n in extras.get("targetNames", [])]
    sigmas = {str(k): float(v) for k, v in extras.get("targetSigmas", {}).items()}
    return names, dict(extras.get("targetNotes", {})), sigmas


def _slider(index: int, name: str, note: str, limits: tuple[float, float], **more) -> dict:
    lo, hi = limits
    slider = {"index": index, "name": name, "note": note, "min": lo, "max": hi}
    slider |= {"step": 0.01 if hi - lo <= 1 else 0.05, "negative": None, "per": 1.0}
    return slider | {"kind": "pca" if name.startswith("pca_") else "viseme"} | more


def semantic_sliders(
    names: Sequence[str], notes: dict[str, str], sigmas: dict[str, float]
) -> list[dict]:
    """One slider per viseme target and ``pca_mean`` (weight 0..1) and one per PCA component.

    A component written as a pair ``pca_k_pos``/``pca_k_neg`` (with ``targetSigmas`` +-s) gets one
    slider ``pca_k`` in units of sigma_k from -s to +s: value a sets weight ``max(a, 0) / s`` on
    the ``pos`` target (``index``) and ``max(-a, 0) / s`` on the ``neg`` one (``negative``;
    ``per`` = s). A single target ``pca_k`` (files before the pair layout) is its own weight in
    :data:`PCA_RANGE`.

    Returns
    -------
    list of dict
        ``index``, ``name``, ``note``, ``min``, ``max``, ``step``, ``kind``, ``negative``
        (target index or None), ``per`` (sigmas per unit weight).
    """
    pairs: dict[int, dict[float, int]] = {}
    for i, name in enumerate(names):
        parsed = parse_pca_target(name)
        if parsed is not None and name in sigmas:
            pairs.setdefault(parsed[0], {})[parsed[1]] = i
    out = []
    for i, name in enumerate(names):
        parsed = parse_pca_target(name)
        pair = pairs.get(parsed[0], {}) if parsed is not None else {}
        if len(pair) == 2 and parsed[1] > 0:
            neg = names[pair[-1.0]]
            per = sigmas[name]
            note = f"alpha_{parsed[0]} in sigma_{parsed[0]}: {notes.get(name, name)}"
            out.append(
                _slider(
                    i, f"pca_{parsed[0]}", note, (sigmas[neg], per), negative=pair[-1.0], per=per
                )
            )
        elif len(pair) != 2:
            limits = PCA_RANGE if re.fullmatch(r"pca_\d+", name) else WEIGHT_RANGE
            out.append(_slider(i, name, notes.get(name, name), limits))
    return out


def quantize(values: np.ndarray) -> tuple[np.ndarray, float]:
    """Values as int16 steps of one scale: ``values ~ steps * scale``; NaN -> :data:`INVALID`.

    Parameters
    ----------
    values : (V, 3) float
        Displacements (head frame, m); NaN rows are invalid vertices.

    Returns
    -------
    steps : (V, 3) int16
        ``round(values / scale)`` within +-32767; :data:`INVALID` (-32768) where NaN.
    scale : float
        ``max |values| / 32767`` (1 when all are zero or NaN): the error is at most scale / 2.
    """
    values = np.asarray(values, dtype=np.float64)
    invalid = ~np.isfinite(values)
    peak = float(np.abs(values[~invalid]).max(initial=0.0))
    scale = peak / 32767 if peak > 0 else 1.0
    steps = np.round(np.where(invalid, 0.0, values) / scale).astype(np.int16)
    steps[invalid] = INVALID
    return steps, scale


def viewer_data(
    h5: h5py.File, takes: Sequence[str], n_modes: int, frame: np.ndarray
) -> tuple[dict, bytes]:
    """What the page's viewer adds to the glTF: the first modes, the expressions' modal
    coordinates and the fitted takes, as a layout (JSON-able) and one binary block.

    Every vector is a (V, 3) displacement from the glTF's base (the neutral, ``/neutral/vertices``)
    in the glTF frame (metres), quantized by :func:`quantize` (int16 little-endian, its own
    scale; ``offset`` in bytes into the block):

    - ``modes[i]``: mode i + 1 per unit modal coordinate (``/modal/modes``, m per mm t^1/2);
      ``range`` is the slider's half range: the coordinate that moves a vertex by
      :data:`MODE_PEAK_MM`, widened to 1.25 times every expression's coordinate;
    - ``presets[j]``: an expression take's first ``n_modes`` coordinates ``q`` and, as
      ``rest``, the displacement of its remaining modes (``sum_{i > n} q_i mode_i``), so that the
      preset shows the expression synthesised from all its coordinates (``Model.expression``);
    - ``takes[j]``: the take's aligned mesh (``/takes/{take}/align/vertices``) minus the
      neutral, :data:`INVALID` where the take has no valid vertex.

    Parameters
    ----------
    h5 : h5py.File
        The subject's store.
    takes : sequence of str
        Take order of the flip-through.
    n_modes : int
        Modes with a slider.
    frame : (4, 4) float
        Neutral frame (mm) -> glTF frame (m): its 3 x 3 part maps the displacements.

    Returns
    -------
    layout : dict
    block : bytes
    """
    rot = np.asarray(frame, dtype=np.float64)[:3, :3]
    neutral = h5[paths.neutral("vertices")][()]
    chunks: list[bytes] = []
    size = 0

    def add(displacement_mm: np.ndarray) -> dict:
        nonlocal size
        steps, scale = quantize(displacement_mm @ rot.T)
        chunks.append(steps.astype("<i2").tobytes())
        entry = {"offset": size, "scale": scale}
        size += len(chunks[-1])
        return entry

    layout: dict = {"vertices": len(neutral), "modes": [], "presets": [], "takes": []}
    modes = h5[paths.modal("modes")][()] if paths.modal("modes") in h5 else np.zeros((0, 1, 3))
    freqs = h5[paths.modal("frequencies_hz")][()] if modes.size else []
    n = min(int(n_modes), len(modes))
    exprs = sorted(h5[paths.EXPRESSIONS]) if paths.EXPRESSIONS in h5 else []
    coords = {
        t: h5[paths.expression(t, "coordinates")][()]
        for t in exprs
        if paths.expression(t, "coordinates") in h5
    }
    for i in range(n):
        peak = float(np.linalg.norm(modes[i], axis=1).max())
        half = MODE_PEAK_MM / peak if peak > 0 else 1.0
        half = max([half, *(1.25 * abs(float(q[i])) for q in coords.values())])
        layout["modes"].append(
            {"mode": i + 1, "frequency_hz": float(freqs[i]), "range": half} | add(modes[i])
        )
    for take, q in coords.items():
        preset = {"take": take, "label": _attr(h5, paths.take(take), "label"), "q": q[:n].tolist()}
        preset["modes"] = len(q)
        if len(q) > n:
            preset["rest"] = add(np.tensordot(q[n:], modes[n : len(q)], axes=1))
        layout["presets"].append(preset)
    for take in takes:
        if paths.align(take, "vertices") not in h5:
            continue
        aligned = h5[paths.align(take, "vertices")][()]
        ok = h5[paths.align(take, "ok")][()] if paths.align(take, "ok") in h5 else True
        entry = {
            "take": take,
            "kind": _attr(h5, paths.take(take), "kind"),
            "label": _attr(h5, paths.take(take), "label"),
            "valid": int(np.isfinite(aligned).all(axis=1).sum()),
            "aligned": bool(ok),
        }
        layout["takes"].append(entry | add(aligned - neutral))
    return layout, b"".join(chunks)


def _sigma_convention(h5: h5py.File) -> str:
    if paths.pca("sigma_convention") not in h5:
        return ""
    value = h5[paths.pca("sigma_convention")][()]
    return value.decode() if isinstance(value, bytes) else str(value)


def _attr(h5: h5py.File, group: str, key: str) -> str:
    value = h5[group].attrs.get(key, "") if group in h5 else ""
    return value.decode() if isinstance(value, bytes) else str(value)


def _missing(h5: h5py.File, layout: dict | None, names: Sequence[str]) -> list[str]:
    """What the viewer cannot show for this subject, and why (the store's /skipped reasons);
    without a ``layout``, only what the glTF lacks."""
    skipped = skipped_stages(h5)
    why = "; ".join(f"{k}: {v}" for k, v in skipped.items())
    out = []
    if not any(not n.startswith("pca_") for n in names):
        out.append("No viseme sliders: the subject has no viseme models.")
    if not any(n.startswith("pca_") for n in names):
        out.append("No PCA sliders: the subject has no PCA (it needs viseme takes).")
    if layout is not None and not layout["modes"]:
        out.append("No modal sliders: the store holds no modal basis.")
    if layout is not None and not layout["presets"]:
        out.append("No expression presets: the subject has no expression takes.")
    if layout is not None and not layout["takes"]:
        out.append("No fitted takes to flip through: the store holds no aligned take meshes.")
    if out and why:
        out.append(f"Skipped stages: {why}.")
    return out


def viewer_context(
    glb: str | Path | None,
    h5: h5py.File,
    takes: Sequence[str],
    n_modes: int,
    three_dir: str | Path = THREE_DIR,
) -> tuple[dict, str | None]:
    """The viewer section's template context and its script (None, with ``unavailable`` saying
    why, when there is no ``.glb`` or three.js is not installed).

    Raises
    ------
    InputError
        An unreadable ``.glb``, or one whose vertex count differs from the store's.
    """
    if glb is None:
        return {"unavailable": "no glTF file was given"}, None
    glb = Path(glb)
    if not glb.is_file():
        return {"unavailable": f"{glb.name} was not written"}, None
    reason = three_unavailable(three_dir)
    if reason is not None:
        return {"unavailable": reason}, None
    names, notes, sigmas = glb_target_names(glb)
    sliders = semantic_sliders(names, notes, sigmas)
    gltf = _read_glb(glb)
    count = gltf.accessors[gltf.meshes[0].primitives[0].attributes.POSITION].count
    try:
        frame, old = read_glb_frame(glb), None
    except InputError as err:  # a file from before the head frame: its own sliders only
        frame, old = (
            None,
            (
                f"No modal sliders or fitted takes: {glb.name} does not say its frame ({err}); "
                "rerun the morph stage to write it anew."
            ),
        )
    if frame is None:
        layout, block = {"vertices": count, "modes": [], "presets": [], "takes": []}, b""
    else:
        layout, block = viewer_data(h5, takes, n_modes, frame)
    if count != layout["vertices"]:
        raise InputError(glb, f"vertices: {count} in the glTF, {layout['vertices']} in the store")
    context = {
        "glb": base64.b64encode(glb.read_bytes()).decode("ascii"),
        "glb_name": glb.name,
        "glb_kb": glb.stat().st_size / 1024,
        "three_version": three_version(three_dir),
        "sliders": sliders,
        "layout": json.dumps(layout, separators=(",", ":")),
        "data": base64.b64encode(block).decode("ascii"),
        "data_kb": len(block) / 1024,
        "modes": layout["modes"],
        "n_modes_total": len(h5[paths.modal("frequencies_hz")]) if layout["modes"] else 0,
        "presets": layout["presets"],
        "takes": layout["takes"],
        "missing": [old, *_missing(h5, None, names)] if old else _missing(h5, layout, names),
        "sigma": SIGMA_WORDS.get(_sigma_convention(h5), "sigma_k of the store's /pca/sigma"),
    }
    return context, viewer_script()
