"""The shape check of the library: modules, functions and imports kept as CONTRIBUTING.md says.

Reads every module of ``src/scan2morph`` with the standard library's :mod:`ast` (nothing is
imported) and reports, one line per offence (``path:subject: what``):

- a module over :data:`MAX_MODULE_LINES` lines (subject ``<module>``);
- a function or method over :data:`MAX_FUNCTION_LINES` lines, from its ``def`` to its last line
  (subject: its qualified name, ``Class.method``, ``outer.inner``);
- a public function or method (no part of its name starting with ``_``; ``__init__`` counts)
  with more than :data:`MAX_PARAMETERS` parameters, ``self``/``cls`` not counted (subject: its
  name followed by ``(params)``);
- an import of a module in a later layer than the importer's (:data:`LAYERS`; subject
  ``import <module>``), lazy imports inside functions included;
- an import cycle among modules (their module-level imports, ``if TYPE_CHECKING:`` blocks left
  out; subject ``<cycle>`` on the cycle's first module, the cycle named in the message).

``from package import name`` counts as importing ``package.name`` when that is a module.

Offences that are known and owned elsewhere are listed in the allowlist
(``tools/shape_allowlist.txt``, one ``path:subject: reason`` per line, ``#`` comments): they are
not reported. An entry that matches no offence any more is itself reported (stale: remove it),
so the list can only shrink. Exit status 1 when anything is reported.

The layers
----------
CONTRIBUTING.md's flow is ``io -> scan -> template -> landmarks -> align -> refine -> motion ->
morph/modal -> render/report -> stages``: a module may import from its own layer and the layers
before it. The stages come last: each one runs its libraries, the figures and the report
included. Encoded as it stands, with these additions and one correction:

- **base** (correction): ``errors``, ``tol``, ``geometry``, ``jobs`` and the whole ``store``
  package (``store.paths`` builds every store path; ``hdf5``, ``warnings``, ``layout`` and
  ``compare`` read and write the store) are used by every layer, and themselves import only
  each other: they come before ``io``, not after ``stages``. ``sheet`` (the sample sheet, with
  ``units``, its units column, ``sheet_text``, its text cell by cell, and ``sheet_consistency``,
  its checks across rows) and
  ``tables`` (the result tables) import only the base and are placed in it, and so is
  ``offscreen`` (the process's headless OpenGL contexts, shared by the synthetic scanners, the
  mesh-scan reader and the figures), ``open3d_light`` (open3d imported without its web viewer,
  for every layer that registers or samples point clouds), ``version`` (the installed version the store records), ``lazy`` (packages whose names are imported when first used) and ``provenance`` (which code made a result: code fingerprints, git commit, versions).
- **synth** (the synthetic scanners) writes takes in ``io``'s formats: after ``io``.
- **landmarks** (the detector, trained on synthetic heads, reading a take's repaired grid) uses
  ``synth`` and ``scan``: after ``template``, before ``align``.
- **refine** (dense correspondence of the aligned fits) uses ``align``'s region motion: between
  ``align`` and ``motion``.
- **evaluate** (accuracy against the truth) reads motion and the fits: beside ``morph/modal``.
- ``model`` (a built model, read back), ``sweep`` (runs stages) and the package ``__init__``
  come last.

Usage: ``python tools/check_shape.py [--root src] [--allowlist tools/shape_allowlist.txt]``.
"""

from __future__ import annotations

import argparse
import ast
import sys
from dataclasses import dataclass
from pathlib import Path

MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 100
MAX_PARAMETERS = 8

#: The layers, first to last: a module may import from its own layer and earlier ones. Each
#: layer lists module prefixes (a module belongs to the layer of its longest matching prefix).
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (
        "base",
        (
            "scan2morph.errors",
            "scan2morph.tol",
            "scan2morph.geometry",
            "scan2morph.jobs",
            "scan2morph.store",
            "scan2morph.sheet",
            "scan2morph.config_schema",
            "scan2morph.sheet_text",
            "scan2morph.sheet_consistency",
            "scan2morph.units",
            "scan2morph.tables",
            "scan2morph.offscreen",
            "scan2morph.open3d_light",
            "scan2morph.version",
            "scan2morph.lazy",
            "scan2morph.provenance",
        ),
    ),
    ("io", ("scan2morph.io",)),
    ("synth", ("scan2morph.synth",)),
    ("scan", ("scan2morph.scan",)),
    ("template", ("scan2morph.template",)),
    ("landmarks", ("scan2morph.landmarks",)),
    ("align", ("scan2morph.align",)),
    ("refine", ("scan2morph.refine",)),
    ("motion", ("scan2morph.motion",)),
    ("morph/modal", ("scan2morph.morph", "scan2morph.modal", "scan2morph.evaluate")),
    ("render/report", ("scan2morph.render", "scan2morph.report")),
    ("stages", ("scan2morph.stages",)),
    ("top", ("scan2morph.model", "scan2morph.sweep", "scan2morph")),
)

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_ALLOWLIST = ROOT / "tools" / "shape_allowlist.txt"


@dataclass(frozen=True)
class Offence:
    """One offence: ``path`` (as given, e.g. ``src/scan2morph/x.py``), ``subject`` (what in it:
    ``<module>``, a function's name, ``name(params)``, ``import m``, ``<cycle>``) and
    ``message``."""

    path: str
    subject: str
    message: str

    @property
    def key(self) -> str:
        return f"{self.path}:{self.subject}"

    def __str__(self) -> str:
        return f"{self.key}: {self.message}"


def module_name(path: str) -> str:
    """``src/scan2morph/align/icp.py`` -> ``scan2morph.align.icp`` (``__init__`` -> package)."""
    parts = list(Path(path).with_suffix("").parts)
    if "scan2morph" in parts:
        parts = parts[parts.index("scan2morph") :]
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer_of(module: str) -> int | None:
    """Index in :data:`LAYERS` of a module (its longest matching prefix); None if none."""
    best, depth = None, -1
    for k, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > depth:
                best, depth = k, len(prefix)
    return best


def _functions(tree: ast.AST):
    """``(qualname, node, public)`` of every function and method, nested ones included."""

    def walk(node, prefix, public):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{child.name}"
                open_ = public and (not child.name.startswith("_") or child.name == "__init__")
                if isinstance(child, ast.ClassDef):
                    yield from walk(child, name + ".", open_)
                else:
                    yield name, child, open_
                    yield from walk(child, name + ".", False)
            else:
                yield from walk(child, prefix, public)

    yield from walk(tree, "", True)


def _parameters(node: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> int:
    a = node.args
    names = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    n = len(names) + (a.vararg is not None) + (a.kwarg is not None)
    if method and names and names[0].arg in ("self", "cls"):
        n -= 1
    return n


def _imports(tree: ast.AST, module: str, is_package: bool, modules: set[str]):
    """``(target, top_level)`` of every import of a ``scan2morph`` module in ``tree``:
    ``top_level`` is False inside functions and ``if TYPE_CHECKING:`` blocks."""

    def resolve(node: ast.ImportFrom) -> str:
        if node.level == 0:
            return node.module or ""
        base = module.split(".") if is_package else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        return ".".join(base + ([node.module] if node.module else []))

    def walk(node, top):
        for child in ast.iter_child_nodes(node):
            inner = top
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
                inner = False
            elif isinstance(child, ast.If) and "TYPE_CHECKING" in ast.dump(child.test):
                inner = False
            if isinstance(child, ast.Import):
                for alias in child.names:
                    if alias.name.split(".")[0] == "scan2morph":
                        yield alias.name, top
            elif isinstance(child, ast.ImportFrom):
                target = resolve(child)
                if target.split(".")[0] == "scan2morph":
                    subs = [f"{target}.{a.name}" for a in child.names]
                    found = [s for s in subs if s in modules]
                    yield from ((s, top) for s in found)
                    if len(found) < len(subs):
                        yield target, top
            yield from walk(child, inner)

    yield from walk(tree, True)


def check_sources(sources: dict[str, str]) -> list[Offence]:
    """The offences of a set of modules.

    Parameters
    ----------
    sources : dict
        ``{path: source text}``; paths end in ``scan2morph/<...>.py`` (their module names come
        from them).

    Returns
    -------
    list of Offence
        Sorted by path and subject.
    """
    names = {path: module_name(path) for path in sources}
    modules = set(names.values())
    graph: dict[str, set[str]] = {}
    offences: list[Offence] = []
    for path, text in sources.items():
        tree = ast.parse(text, filename=path)
        module = names[path]
        n_lines = len(text.splitlines())
        if n_lines > MAX_MODULE_LINES:
            offences.append(
                Offence(path, "<module>", f"{n_lines} lines (at most {MAX_MODULE_LINES})")
            )
        for qualname, node, public in _functions(tree):
            length = node.end_lineno - node.lineno + 1
            if length > MAX_FUNCTION_LINES:
                offences.append(
                    Offence(path, qualname, f"{length} lines (at most {MAX_FUNCTION_LINES})")
                )
            n = _parameters(node, "." in qualname)
            if public and n > MAX_PARAMETERS:
                offences.append(
                    Offence(
                        path,
                        f"{qualname}(params)",
                        f"{n} parameters (a public function: at most {MAX_PARAMETERS})",
                    )
                )
        mine = layer_of(module)
        graph[module] = set()
        seen = set()
        for target, top in _imports(tree, module, path.endswith("__init__.py"), modules):
            if top and target in modules and target != module:
                graph[module].add(target)
            theirs = layer_of(target)
            if target in seen or mine is None or theirs is None or theirs <= mine:
                continue
            seen.add(target)
            offences.append(
                Offence(
                    path,
                    f"import {target}",
                    f"layer {LAYERS[mine][0]!r} imports from the later layer {LAYERS[theirs][0]!r}",
                )
            )
    paths = {m: p for p, m in names.items()}
    for cycle in _cycles(graph):
        offences.append(
            Offence(paths[cycle[0]], "<cycle>", "import cycle: " + " -> ".join(cycle + cycle[:1]))
        )
    return sorted(offences, key=lambda o: (o.path, o.subject))


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (a list of modules, starting at its smallest) per strongly connected component
    of more than one module (Tarjan's algorithm), and per module importing itself."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    counter = [0]

    def connect(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            components.append(comp)

    for v in sorted(graph):
        if v not in index:
            connect(v)
    cycles = []
    for comp in components:
        if len(comp) > 1:
            members = set(comp)
            start = min(comp)
            cycles.append(_path_back(graph, start, members))
    return sorted(cycles)


def _path_back(graph: dict[str, set[str]], start: str, members: set[str]) -> list[str]:
    """A shortest cycle through ``start`` within ``members`` (breadth-first)."""
    previous = {start: None}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph.get(v, ())):
            if w == start:
                path = [v]
                while previous[path[-1]] is not None:
                    path.append(previous[path[-1]])
                return path[::-1]
            if w in members and w not in previous:
                previous[w] = v
                queue.append(w)
    return [start]


def read_allowlist(text: str) -> dict[str, tuple[int, str]]:
    """``{path:subject: (line number, reason)}`` of an allowlist's text (``#`` comments and
    blank lines skipped; each entry ``path:subject: reason``)."""
    entries = {}
    for k, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        key, sep, reason = line.partition(": ")
        if not sep or not reason.strip():
            raise ValueError(f"allowlist line {k}: expected 'path:subject: reason', got {line!r}")
        entries[key.strip()] = (k, reason.strip())
    return entries


def apply_allowlist(
    offences: list[Offence], entries: dict[str, tuple[int, str]], name: str = "allowlist"
) -> list[str]:
    """The lines to report: offences not in ``entries``, and entries matching no offence
    (stale)."""
    keys = {o.key for o in offences}
    lines = [str(o) for o in offences if o.key not in entries]
    for key, (k, _) in sorted(entries.items(), key=lambda e: e[1][0]):
        if key not in keys:
            lines.append(f"{name}:{k}: stale entry {key}: no such offence any more (remove it)")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=ROOT, help="the repository (default: this)")
    parser.add_argument("--allowlist", type=Path, default=DEFAULT_ALLOWLIST)
    args = parser.parse_args(argv)
    files = sorted((args.root / "src" / "scan2morph").rglob("*.py"))
    sources = {f.relative_to(args.root).as_posix(): f.read_text(encoding="utf-8") for f in files}
    allow = args.allowlist
    entries = read_allowlist(allow.read_text(encoding="utf-8")) if allow.exists() else {}
    shown = allow.relative_to(args.root).as_posix() if allow.is_relative_to(args.root) else allow
    lines = apply_allowlist(check_sources(sources), entries, str(shown))
    for line in lines:
        print(line)
    return 1 if lines else 0


if __name__ == "__main__":
    sys.exit(main())
