"""Which code made a result: fingerprints of the library's code, the git commit, the versions.

A stage's result depends on the library code it runs, not only on its settings and inputs. The
*code fingerprint* of a set of modules (:func:`code_fingerprint`) is the SHA-256 of the code of
every ``scan2morph`` module they import, directly or through other ``scan2morph`` modules, and of
the package data beside those modules (the report's templates, the landmark detector's
``model.npz``) and of the files outside the package they read (:data:`OUTSIDE_FILES`: the
report's 3D viewer bundle). Imports are found statically, with :mod:`ast` (nothing is imported): top-level
ones and those inside functions, not those under ``if TYPE_CHECKING:``; ``from package import
name`` counts the module ``package.name`` when there is one, else the package, and for a package
whose names are imported when first used (:func:`scan2morph.lazy.lazy_exports`) the module the
name comes from. A package's ``__init__`` counts only where something imports from it.

A module's code is its syntax tree without docstrings (``ast.dump``): an edit of a comment, a
docstring or the layout changes nothing; any change of code changes the fingerprint (so does a
new Python version, whose syntax trees may differ). Each module is parsed once per process and
source, and what a parse found is kept between processes by the source's SHA-256
(:func:`cache_file`, one file per Python version): parsing the whole library takes about 1
CPU-s, reading it back a few ms, which every Snakemake (the run's, and under SLURM each job's)
pays when it computes the stages' fingerprints.

The store also records the git commit of the checkout the library runs from (with whether its
tracked files differ from it) and the versions of its main dependencies (:func:`run_provenance`).
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

#: The library's package folder (``src/scan2morph`` in a checkout).
PACKAGE_DIR = Path(__file__).resolve().parent
#: The library's top-level package name.
PACKAGE = "scan2morph"
#: Files in the package folders that are not package data.
NOT_DATA = ("py.typed",)
#: Files outside the package that a module's results depend on (module -> paths in the
#: repository, :func:`scan2morph.provenance.repository_dir`): the report inlines the 3D viewer
#: as ``make setup`` bundled it and names the three.js version
#: (:data:`scan2morph.report.viewer.VIEWER_BUNDLE`, ``THREE_DIR``).
OUTSIDE_FILES: dict[str, tuple[str, ...]] = {
    "scan2morph.report.viewer": (
        "tools/viewer/dist/viewer.js",
        "tools/viewer/node_modules/three/package.json",
    ),
}
#: The dependencies whose versions a store records (display name -> distribution names tried).
STORE_DEPENDENCIES: dict[str, tuple[str, ...]] = {
    "numpy": ("numpy",),
    "scipy": ("scipy",),
    "opencv": (
        "opencv-contrib-python-headless",
        "opencv-contrib-python",
        "opencv-python-headless",
        "opencv-python",
    ),
    "open3d": ("open3d", "open3d-cpu"),
    "h5py": ("h5py",),
    "snakemake": ("snakemake",),
}
#: Seconds a git call may take before the commit is left out.
GIT_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class _Module:
    """One parsed module: the SHA-256 of its code, its imports of ``scan2morph`` modules
    (``(module, names)``: names None for ``import module``), its lazily exported names (name ->
    module) and its folder."""

    code: str
    imports: tuple[tuple[str, tuple[str, ...] | None], ...]
    lazy: Mapping[str, str]
    folder: Path


def module_file(module: str, package_dir: Path = PACKAGE_DIR) -> Path | None:
    """The source file of a ``scan2morph`` module (a package's ``__init__.py``), None if none."""
    parts = module.split(".")
    if parts[0] != PACKAGE:
        return None
    base = package_dir.joinpath(*parts[1:])
    for path in (base / "__init__.py", base.with_suffix(".py")):
        if path.is_file():
            return path
    return None


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    """The tree without the docstrings of its module, classes and functions (in place)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if (
                body
                and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)
            ):
                node.body = body[1:] or [ast.Pass()]
    return tree


def code_sha256(source: str | bytes) -> str:
    """SHA-256 (hex) of a module's code: its syntax tree without docstrings, comments or layout.

    Parameters
    ----------
    source : str or bytes
        The module's source text.

    Returns
    -------
    str
        Hex SHA-256 (64 characters) of ``ast.dump`` of the tree without docstrings.
    """
    return _tree_sha256(ast.parse(source))


def _tree_sha256(tree: ast.AST) -> str:
    return hashlib.sha256(ast.dump(_strip_docstrings(tree)).encode()).hexdigest()


def _import_records(tree: ast.AST, module: str, is_package: bool):
    """``(target, names)`` of every import of a ``scan2morph`` module outside ``if
    TYPE_CHECKING:`` blocks (names None for ``import target``)."""
    base = module.split(".") if is_package else module.split(".")[:-1]
    stack = [tree]
    while stack:
        node = stack.pop()
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.dump(child.test):
                stack.append(ast.Module(body=child.orelse, type_ignores=[]))
                continue
            if isinstance(child, ast.Import):
                for alias in child.names:
                    if alias.name.split(".")[0] == PACKAGE:
                        yield alias.name, None
            elif isinstance(child, ast.ImportFrom):
                target = child.module or ""
                if child.level:
                    target = ".".join(
                        base[: len(base) - (child.level - 1)] + ([target] if target else [])
                    )
                if target.split(".")[0] == PACKAGE:
                    yield target, tuple(a.name for a in child.names)
            stack.append(child)


def _lazy_exports(tree: ast.AST, module: str) -> dict[str, str]:
    """Name -> module of a package's ``lazy_exports(__name__, {module: (names, ...)})`` call."""
    out: dict[str, str] = {}
    for node in ast.walk(tree):
        if not (
            isinstance(node, ast.Call)
            and getattr(node.func, "id", getattr(node.func, "attr", None)) == "lazy_exports"
            and len(node.args) >= 2
            and isinstance(node.args[1], ast.Dict)
        ):
            continue
        for key, value in zip(node.args[1].keys, node.args[1].values, strict=True):
            names = value.elts if isinstance(value, ast.Tuple | ast.List) else []
            for name in names:
                if isinstance(key, ast.Constant) and isinstance(name, ast.Constant):
                    out[str(name.value)] = f"{module}.{key.value}"
    return out


def cache_file() -> Path:
    """Where parses are kept between processes: ``$XDG_CACHE_HOME/scan2morph`` (default
    ``~/.cache/scan2morph``), ``parsed-{python}.json`` (syntax trees differ between versions)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "scan2morph" / f"parsed-{sys.implementation.cache_tag}.json"


@functools.cache
def _disk_cache() -> dict:
    """The parses kept on disk (key -> [code, imports, lazy]); empty when there are none or
    the file cannot be read (it is only a cache)."""
    try:
        data = json.loads(cache_file().read_text(encoding="utf-8"))
    except (OSError, ValueError, RuntimeError):  # RuntimeError: no home folder
        return {}
    return data if isinstance(data, dict) else {}


def _save_disk_cache() -> None:
    """Write the parses to :func:`cache_file` (atomically; an unwritable place is no error);
    past :data:`CACHE_ENTRIES` entries only those this process used are kept."""
    kept = _disk_cache()
    if len(kept) > CACHE_ENTRIES:
        kept = {k: v for k, v in kept.items() if k in _PARSED_USED}
    try:
        path = cache_file()
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, delete=False) as tmp:
            json.dump(kept, tmp)
        os.replace(tmp.name, path)
    except (OSError, RuntimeError):
        pass
    _PARSED_NEW.clear()


@functools.cache
def _parse(source: bytes, module: str, is_package: bool) -> tuple:
    """A module's code hash, imports and lazy exports, parsed once per process and source, and
    kept on disk by the source's SHA-256 (:func:`cache_file`)."""
    key = f"{module}:{int(is_package)}:{hashlib.sha256(source).hexdigest()}"
    _PARSED_USED.add(key)
    kept = _disk_cache().get(key)
    if isinstance(kept, list) and len(kept) == 3:
        code, records, lazy = kept
        return code, tuple((t, None if n is None else tuple(n)) for t, n in records), lazy
    tree = ast.parse(source)
    records = tuple(_import_records(tree, module, is_package))
    parsed = (_tree_sha256(tree), records, _lazy_exports(tree, module))
    _disk_cache()[key] = [parsed[0], [[t, n] for t, n in records], parsed[2]]
    _PARSED_NEW.append(key)
    return parsed


#: Keys parsed in this process and not yet written to :func:`cache_file`; keys used by it.
_PARSED_NEW: list[str] = []
_PARSED_USED: set[str] = set()
#: Entries the parse cache keeps before it drops those the writing process did not use.
CACHE_ENTRIES = 5000


def _parsed(module: str, package_dir: Path = PACKAGE_DIR) -> _Module | None:
    """A module as it is now (None: no such module); its source is parsed once per process."""
    path = module_file(module, package_dir)
    if path is None:
        return None
    code, records, lazy = _parse(path.read_bytes(), module, path.name == "__init__.py")
    return _Module(code, records, lazy, path.parent)


def _targets(record: tuple[str, tuple[str, ...] | None], parsed) -> set[str]:
    """The modules one import record brings in (see the module's docstring); ``parsed(module)``
    gives a module's parse (None: no such module)."""
    target, names = record
    package = parsed(target)
    lazy = package.lazy if package is not None else {}
    if names is None or "*" in names:
        return ({target} | set(lazy.values())) if package is not None else set()
    out: set[str] = set()
    for name in names:
        if parsed(f"{target}.{name}") is not None:
            out.add(f"{target}.{name}")
        elif package is not None:
            out.add(target)
            if name in lazy:
                out.add(lazy[name])
    return out


def module_closure(roots: Iterable[str], package_dir: Path = PACKAGE_DIR) -> tuple[str, ...]:
    """The ``scan2morph`` modules ``roots`` run: themselves and what they import, transitively.

    Parameters
    ----------
    roots : iterable of str
        Module names (``scan2morph.stages.fit``); one that does not exist is left out.
    package_dir : Path
        The package's folder (tests give another one).

    Returns
    -------
    tuple of str
        The modules, sorted.
    """
    return tuple(sorted(_closure(roots, package_dir)))


def _closure(roots: Iterable[str], package_dir: Path) -> dict[str, _Module]:
    """:func:`module_closure`, each module with its parse."""
    memo: dict[str, _Module | None] = {}

    def parsed(module: str) -> _Module | None:
        if module not in memo:
            memo[module] = _parsed(module, package_dir)
        return memo[module]

    seen: dict[str, _Module] = {}
    todo = list(roots)
    while todo:
        module = todo.pop()
        if module in seen or parsed(module) is None:
            continue
        seen[module] = parsed(module)
        for record in seen[module].imports:
            todo.extend(_targets(record, parsed) - seen.keys())
    return seen


def _package_data(folder: Path) -> tuple[tuple[str, str], ...]:
    """``(path, sha256)`` of the package data in a package's folder: every file but Python
    sources, caches and :data:`NOT_DATA`, in sub-folders too unless they are packages."""
    out = []
    todo = [folder]
    while todo:
        here = todo.pop()
        for path in sorted(here.iterdir()):
            if path.is_dir():
                if path.name != "__pycache__" and not (path / "__init__.py").is_file():
                    todo.append(path)
            elif path.suffix not in (".py", ".pyc") and path.name not in NOT_DATA:
                stat = path.stat()
                digest = _file_sha256(path, stat.st_mtime_ns, stat.st_size)
                out.append((path.relative_to(folder).as_posix(), digest))
    return tuple(sorted(out))


@functools.cache
def _file_sha256(path: Path, mtime_ns: int, size: int) -> str:
    """SHA-256 of a file, read once per process while its time and size stay the same."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def repository_dir(package_dir: Path = PACKAGE_DIR) -> Path:
    """The folder of the checkout (or installation) above the package's: ``src/..``."""
    return package_dir.parents[1]


def _outside_files(modules: Iterable[str], package_dir: Path) -> dict[str, str | None]:
    """SHA-256 of the :data:`OUTSIDE_FILES` of ``modules`` by path (None: missing)."""
    out: dict[str, str | None] = {}
    for module in modules:
        for name in OUTSIDE_FILES.get(module, ()):
            path = repository_dir(package_dir) / name
            stat = path.stat() if path.is_file() else None
            out[name] = stat and _file_sha256(path, stat.st_mtime_ns, stat.st_size)
    return out


def code_fingerprint(roots: Iterable[str], package_dir: Path = PACKAGE_DIR) -> str:
    """The fingerprint of the code ``roots`` run (:func:`module_closure`) and of its package data.

    Parameters
    ----------
    roots : iterable of str
        Module names.
    package_dir : Path
        The package's folder.

    Returns
    -------
    str
        Hex SHA-256 (64 characters) of every module's code (:func:`code_sha256`), of the data
        files in the folders of those modules and of their :data:`OUTSIDE_FILES`, by name: the
        same for the same code in any process.
    """
    parsed = dict(sorted(_closure(roots, package_dir).items()))
    if _PARSED_NEW:
        _save_disk_cache()
    folders = sorted({p.folder for p in parsed.values()})
    data = {
        f"{folder.relative_to(package_dir).as_posix()}/{name}": digest
        for folder in folders
        for name, digest in _package_data(folder)
    }
    modules = {m: p.code for m, p in parsed.items()}
    outside = _outside_files(parsed, package_dir)
    text = json.dumps({"modules": modules, "data": data, "outside": outside}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def distribution_version(names: Sequence[str]) -> str | None:
    """Version of the first installed distribution among ``names`` (None: none installed)."""
    for name in names:
        try:
            return version(name)
        except PackageNotFoundError:
            continue
    return None


def dependency_versions(
    dependencies: Mapping[str, Sequence[str]] = STORE_DEPENDENCIES,
) -> dict[str, str]:
    """Python's version and those of the installed ``dependencies`` (display name ->
    distribution names tried); one that is not installed is left out."""
    out = {"python": sys.version.split()[0]}
    for name, dists in dependencies.items():
        found = distribution_version(dists)
        if found is not None:
            out[name] = found
    return out


def _git(repo: Path, *args: str) -> str:
    done = subprocess.run(
        ["git", "-C", str(repo), *args],
        capture_output=True,
        text=True,
        timeout=GIT_TIMEOUT_S,
        check=True,
    )
    return done.stdout


def git_state(repo: Path | None = None) -> dict[str, object]:
    """The git commit of the checkout the library runs from, and whether it is dirty.

    Parameters
    ----------
    repo : Path, optional
        The repository's folder; default the one above ``src/scan2morph`` when that is a git
        checkout (it has ``.git``), else none.

    Returns
    -------
    dict
        ``git_commit`` (hex) and ``git_dirty`` (bool: tracked files differ from the commit);
        empty when there is no checkout, no git, or git fails (never an error).
    """
    repo = repository_dir() if repo is None else Path(repo)
    if not (repo / ".git").exists():
        return {}
    try:
        commit = _git(repo, "rev-parse", "HEAD").strip()
        dirty = bool(_git(repo, "status", "--porcelain", "--untracked-files=no").strip())
    except (OSError, subprocess.SubprocessError):
        return {}
    return {"git_commit": commit, "git_dirty": dirty}


def run_provenance(code: str, repo: Path | None = None) -> dict[str, object]:
    """The root attributes that say which code made a store.

    Parameters
    ----------
    code : str
        The code fingerprint of what made it (:func:`code_fingerprint`).
    repo : Path, optional
        The checkout (:func:`git_state`).

    Returns
    -------
    dict
        ``code_sha256``, ``dependencies`` (JSON: :func:`dependency_versions`), and when the
        library runs from a git checkout ``git_commit`` and ``git_dirty``.
    """
    attrs: dict[str, object] = {"code_sha256": code}
    attrs |= git_state(repo)
    attrs["dependencies"] = json.dumps(dependency_versions(), sort_keys=True)
    return attrs


__all__ = [
    "OUTSIDE_FILES",
    "PACKAGE_DIR",
    "STORE_DEPENDENCIES",
    "code_fingerprint",
    "code_sha256",
    "dependency_versions",
    "distribution_version",
    "git_state",
    "module_closure",
    "module_file",
    "repository_dir",
    "run_provenance",
]
