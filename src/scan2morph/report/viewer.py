"""The report's interactive 3D viewer: the subject's glTF in three.js, inside the one-file page.

The page must open from disk with no network, so everything is inline: the ``.glb`` as base64 in
a ``data-glb`` attribute, and one ``<script type="module">`` that bundles three.js (the npm package
``three``, pinned in ``tools/viewer/package-lock.json`` and installed by ``make setup`` with
``npm ci``: its prebuilt ``build/three.module.min.js`` and the ``GLTFLoader`` and
``OrbitControls`` add-ons) with our own ``viewer/viewer.js``. The page's Content-Security-Policy
allows exactly that script, by its SHA-256 hash (:func:`script_hash`).

Bundling (:func:`bundle`) rewrites ES modules into one: every imported module becomes an arrow
function run once, in dependency order, whose ``export`` list becomes its return value
(``const __s2m_1 = (() => { ...; return {GLTFLoader}; })();``), and each
``import {a, b as c} from 'x'`` becomes ``const {a, b: c} = __s2m_k;``. Each module keeps its own
scope, so the minified names of three.js cannot collide with the add-ons'. Only the static import
and export forms these files use are supported; anything else raises.

The viewer shows the mesh under a camera on +Z looking down -Z (+Y up: the head frame of
:mod:`scan2morph.io.gltf`), orbit controls, one range slider per morph target (visemes and
``pca_mean`` 0..1, ``pca_k`` -3..3: the targets are ``sigma_k e_k``), texture on/off and wireframe.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import html
import json
import re
from pathlib import Path

from scan2morph.errors import InputError
from scan2morph.io.gltf import _read_glb

#: The npm package that pins three.js (``npm ci`` installs it into ``node_modules``).
VIEWER_PACKAGE = Path(__file__).resolve().parents[3] / "tools" / "viewer"
THREE_DIR = VIEWER_PACKAGE / "node_modules" / "three"
#: Our viewer module (imports ``three`` and ``three/addons/...`` like any three.js app).
VIEWER_JS = Path(__file__).with_name("viewer") / "viewer.js"
#: Range of the weight sliders: ``pca_k`` in standard deviations, everything else 0..1.
PCA_RANGE = (-3.0, 3.0)
WEIGHT_RANGE = (0.0, 1.0)
#: The CSP sources the viewer needs besides its script: GLTFLoader hands the embedded texture to
#: the browser as a ``blob:`` URL, which it fetches.
CSP_SOURCES = "img-src data: blob:; connect-src data: blob:"

_IMPORT = re.compile(
    r"^[ \t]*import\s*(?:\{(?P<names>[^}]*)\}|\*\s*as\s+(?P<star>[\w$]+))\s*"
    r"from\s*(?P<q>['\"])(?P<spec>[^'\"]+)(?P=q)\s*;?",
    re.M,
)
_EXPORT_LIST = re.compile(r"(?:^|(?<=[;}\n]))[ \t]*export\s*\{(?P<names>[^}]*)\}\s*;?", re.M)
_EXPORT_DECL = re.compile(
    r"^[ \t]*export\s+(?=(?:async\s+)?(?:function\*?|class|const|let|var)\s)"
    r"(?P<decl>(?:async\s+)?(?:function\*?|class|const|let|var)\s+(?P<name>[\w$]+))",
    re.M,
)


def three_unavailable(three_dir: str | Path = THREE_DIR) -> str | None:
    """Why the viewer cannot be built (three.js not installed), or None when it can."""
    three_dir = Path(three_dir)
    needed = [_resolve("three", None, three_dir)]
    needed += [_resolve(s, None, three_dir) for s in _ADDONS]
    missing = [p for p in needed if not p.is_file()]
    if missing:
        return (
            f"three.js is not installed ({missing[0]} is missing): run `make setup` "
            "(npm ci in tools/viewer) and rebuild the report"
        )
    return None


def three_version(three_dir: str | Path = THREE_DIR) -> str:
    """The installed three.js version (its ``package.json``)."""
    return json.loads((Path(three_dir) / "package.json").read_text())["version"]


_ADDONS = ("three/addons/loaders/GLTFLoader.js", "three/addons/controls/OrbitControls.js")


def _resolve(spec: str, importer: Path | None, three_dir: Path) -> Path:
    if spec == "three":
        return three_dir / "build" / "three.module.min.js"
    if spec.startswith("three/addons/"):
        return three_dir / "examples" / "jsm" / spec.removeprefix("three/addons/")
    if spec.startswith(".") and importer is not None:
        return (importer.parent / spec).resolve()
    raise InputError(str(importer), f"bundle: cannot resolve import {spec!r}")


def _pairs(names: str, sep: str) -> list[tuple[str, str]]:
    """``a, b as c`` -> [(a, a), (b, c)] (local name, exported or imported name per ``sep``)."""
    out = []
    for item in names.split(","):
        item = item.strip()
        if item:
            left, _, right = item.partition(" as ")
            out.append((left.strip(), (right or left).strip()))
    return out


def _rewrite(path: Path, code: str, ids: dict[Path, str], three_dir: Path) -> tuple[str, list]:
    """A module's code with its imports bound from the bundled modules and its exports removed;
    the export list as (local, exported) pairs."""

    def imports(m: re.Match) -> str:
        source = ids[_resolve(m["spec"], path, three_dir)]
        if m["star"]:
            return f"const {m['star']} = {source};"
        bound = ", ".join(f"{a}: {b}" for a, b in _pairs(m["names"], " as "))
        return f"const {{ {bound} }} = {source};"

    code = _IMPORT.sub(imports, code)
    exports: list[tuple[str, str]] = []

    def export_list(m: re.Match) -> str:
        exports.extend(_pairs(m["names"], " as "))
        return ""

    def export_decl(m: re.Match) -> str:
        exports.append((m["name"], m["name"]))
        return m.group(0).replace("export", "", 1).lstrip()

    code = _EXPORT_LIST.sub(export_list, code)
    code = _EXPORT_DECL.sub(export_decl, code)
    left = re.search(r"^[ \t]*(?:import|export)\b(?!\s*\()", code, re.M)
    if left or "import.meta" in code:
        where = left.group(0).strip() if left else "import.meta"
        raise InputError(path, f"bundle: unsupported module syntax ({where!r})")
    return code, exports


def _imports_of(path: Path, three_dir: Path) -> list[Path]:
    return [_resolve(m["spec"], path, three_dir) for m in _IMPORT.finditer(path.read_text())]


def bundle(entry: str | Path, three_dir: str | Path = THREE_DIR) -> str:
    """One module script of ``entry`` and every module it imports (see the module docstring).

    Raises
    ------
    InputError
        A module is missing, imports something other than ``three``, ``three/addons/...`` or a
        relative path, uses module syntax the rewrite does not handle, or contains text that
        would end an inline ``<script>`` early.
    """
    entry, three_dir = Path(entry).resolve(), Path(three_dir).resolve()
    order: list[Path] = []

    def visit(path: Path, stack: tuple[Path, ...]) -> None:
        if path in order:
            return
        if path in stack:
            raise InputError(path, "bundle: circular import")
        if not path.is_file():
            raise InputError(path, "bundle: module not found (make setup installs three.js)")
        for dep in _imports_of(path, three_dir):
            visit(dep, (*stack, path))
        order.append(path)

    visit(entry, ())
    ids = {p: f"__s2m_{i}" for i, p in enumerate(order)}
    parts = []
    for path in order:
        code, exports = _rewrite(path, path.read_text(), ids, three_dir)
        if path == entry:
            parts.append(code)
            continue
        values = ", ".join(f"{b}: {a}" for a, b in exports)
        parts.append(f"const {ids[path]} = (() => {{\n{code}\nreturn {{ {values} }};\n}})();\n")
    script = "\n".join(parts)
    if re.search(r"</script|<!--", script, re.I):
        raise InputError(entry, "bundle: the code contains '</script' or '<!--'")
    return script


@functools.lru_cache(maxsize=4)
def _viewer_script(entry: str, three_dir: str, stamp: tuple) -> str:
    return bundle(entry, three_dir)


def viewer_script(three_dir: str | Path = THREE_DIR) -> str:
    """The viewer's bundled module script (cached while the files are unchanged)."""
    files = [VIEWER_JS, _resolve("three", None, Path(three_dir))]
    stamp = tuple(f.stat().st_mtime_ns for f in files if f.is_file())
    return _viewer_script(str(VIEWER_JS), str(three_dir), stamp)


def script_hash(script: str) -> str:
    """The CSP source that allows exactly this inline script: ``'sha256-...'``."""
    digest = hashlib.sha256(script.encode("utf-8")).digest()
    return f"'sha256-{base64.b64encode(digest).decode('ascii')}'"


def glb_target_names(path: str | Path) -> tuple[list[str], dict[str, str]]:
    """The morph target names of a ``.glb`` (``mesh.extras.targetNames``) and their notes."""
    gltf = _read_glb(Path(path))
    extras = (gltf.meshes[0].extras or {}) if gltf.meshes else {}
    return [str(n) for n in extras.get("targetNames", [])], dict(extras.get("targetNotes", {}))


def _range(name: str) -> tuple[float, float]:
    return PCA_RANGE if re.fullmatch(r"pca_\d+", name) else WEIGHT_RANGE


def _esc(value: object) -> str:
    return html.escape(str(value), quote=True)


def viewer_html(glb: str | Path, three_dir: str | Path = THREE_DIR) -> tuple[str, str | None]:
    """The viewer section's HTML and its script (None, with a note instead, when three.js is not
    installed or there is no ``.glb``).

    Raises
    ------
    InputError
        An unreadable ``.glb``.
    """
    glb = Path(glb)
    if not glb.is_file():
        return f'<p class="note">No 3D viewer: {_esc(glb.name)} was not written.</p>', None
    reason = three_unavailable(three_dir)
    if reason is not None:
        return f'<p class="note">No 3D viewer: {_esc(reason)}.</p>', None
    names, notes = glb_target_names(glb)
    sliders = []
    for i, name in enumerate(names):
        lo, hi = _range(name)
        step = 0.01 if hi - lo <= 1 else 0.05
        sliders.append(
            f'<label title="{_esc(notes.get(name, name))}"><span>{_esc(name)}</span>'
            f'<input type="range" data-target="{i}" name="{_esc(name)}" min="{lo:g}" '
            f'max="{hi:g}" step="{step:g}" value="0"><output>0</output></label>'
        )
    data = base64.b64encode(glb.read_bytes()).decode("ascii")
    size_kb = glb.stat().st_size / 1024
    caption = (
        f"{glb.name} ({size_kb:.0f} kB) in three.js {three_version(three_dir)}: drag to orbit, "
        "wheel to zoom, right-drag to pan. Camera on +Z (the head frame: +Y up, +Z out of the "
        "face). Sliders: morph target weights (viseme takes and pca_mean 0..1; pca_k in "
        "standard deviations, with pca_mean at 1 they give Eq. 2)."
    )
    body = (
        f'<div id="viewer3d" class="viewer" data-state="loading" data-glb="{data}">'
        '<canvas width="640" height="480"></canvas><div class="controls">'
        '<label><input type="checkbox" name="texture" checked> texture</label>'
        '<label><input type="checkbox" name="wireframe"> wireframe</label>'
        '<button type="button" name="reset">reset weights</button>'
        f'<div class="sliders">{"".join(sliders)}</div></div>'
        f'<p class="note viewer-status">Loading the 3D viewer (needs JavaScript and WebGL)...</p>'
        f"<p>{_esc(caption)}</p></div>"
    )
    return body, viewer_script(three_dir)


#: The viewer's layout (added to the page's style sheet).
CSS = """
.viewer{display:flex;flex-wrap:wrap;gap:1rem;align-items:flex-start}
.viewer canvas{border:1px solid #ccc;max-width:100%;touch-action:none}
.viewer .controls{flex:1;min-width:16rem;font-size:.85rem}
.viewer .sliders{max-height:420px;overflow-y:auto;margin-top:.4rem}
.viewer .sliders label{display:grid;grid-template-columns:7rem 1fr 3rem;gap:.4rem;
align-items:center}.viewer output{font-variant-numeric:tabular-nums;text-align:right}
.viewer .controls>label{margin-right:1rem}.viewer>p{flex-basis:100%;margin:0}
"""
