"""Which code made a result: code fingerprints by static import analysis, the git commit and
the dependencies' versions (:mod:`scan2morph.provenance`)."""

from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from scan2morph import provenance
from scan2morph.provenance import (
    OUTSIDE_FILES,
    PACKAGE_DIR,
    cache_file,
    code_fingerprint,
    code_sha256,
    dependency_versions,
    git_state,
    module_closure,
    repository_dir,
    run_provenance,
)

#: A small library: ``a`` imports ``b`` at the top and ``c`` inside a function, ``d`` only for
#: type checking, and ``lazy.f`` through its package's names imported when first used.
LIBRARY = {
    "__init__.py": '"""The package."""\n',
    "a.py": (
        '"""Module a."""\n'
        "from typing import TYPE_CHECKING\n"
        "from scan2morph import b\n"
        "from scan2morph.lazy_pkg import helper\n"
        "if TYPE_CHECKING:\n"
        "    from scan2morph import d\n"
        "\n"
        "def run(x):\n"
        '    """Run."""\n'
        "    from scan2morph.c import twice  # lazily\n"
        "    return twice(b.one(x)) + helper(x)\n"
    ),
    "b.py": '"""Module b."""\n\ndef one(x):\n    return x + 1\n',
    "c.py": "def twice(x):\n    return 2 * x\n",
    "d.py": "X = 1\n",
    "e.py": "from scan2morph import d\n",
    "lazy_pkg/__init__.py": (
        "from scan2morph.lazy import lazy_exports\n"
        "__getattr__, __dir__, __all__ = lazy_exports(\n"
        '    __name__, {"f": ("helper",), "g": ("other",)}\n'
        ")\n"
    ),
    "lazy_pkg/f.py": "def helper(x):\n    return x\n",
    "lazy_pkg/g.py": "def other(x):\n    return x\n",
    "lazy_pkg/table.csv": "a,b\n",
}


@pytest.fixture(autouse=True)
def parse_cache(tmp_path, monkeypatch):
    """Each test with a parse cache of its own (the disk cache under ``tmp_path``), empty."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    provenance._parse.cache_clear()
    provenance._disk_cache.cache_clear()
    yield
    provenance._parse.cache_clear()
    provenance._disk_cache.cache_clear()


@pytest.fixture
def library(tmp_path):
    """The small library in ``tmp_path/src/scan2morph``: its folder."""
    root = tmp_path / "src" / "scan2morph"
    for name, text in LIBRARY.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return root


def test_code_ignores_docstrings_comments_and_layout_but_not_code():
    base = code_sha256('"""Doc."""\ndef f(x):\n    """Doc."""\n    return x + 1\n')
    same = code_sha256('"""Other."""\n\n\ndef f(x):  # note\n    """Other."""\n    return x+1\n')
    assert same == base
    assert code_sha256('"""Doc."""\ndef f(x):\n    return x + 2\n') != base
    assert code_sha256("def f(x):\n    return x + 1\n") == base  # no docstring at all


def test_the_closure_follows_imports_lazy_ones_and_lazy_packages_not_type_checking(library):
    assert module_closure(["scan2morph.a"], library) == (
        "scan2morph.a",
        "scan2morph.b",
        "scan2morph.c",
        "scan2morph.lazy_pkg",
        "scan2morph.lazy_pkg.f",
    )
    assert module_closure(["scan2morph.e"], library) == ("scan2morph.d", "scan2morph.e")
    assert module_closure(["scan2morph.missing"], library) == ()


def test_a_code_change_changes_the_fingerprints_of_the_modules_that_import_it(library):
    before = {m: code_fingerprint([m], library) for m in ("scan2morph.a", "scan2morph.e")}
    (library / "c.py").write_text("def twice(x):\n    return 3 * x\n")
    after = {m: code_fingerprint([m], library) for m in before}
    assert after["scan2morph.a"] != before["scan2morph.a"]
    assert after["scan2morph.e"] == before["scan2morph.e"]
    # a change only under TYPE_CHECKING's import reaches nothing that runs
    (library / "d.py").write_text("X = 2\n")
    assert code_fingerprint(["scan2morph.a"], library) == after["scan2morph.a"]
    assert code_fingerprint(["scan2morph.e"], library) != after["scan2morph.e"]


def test_a_docstring_or_comment_edit_changes_no_fingerprint(library):
    before = code_fingerprint(["scan2morph.a"], library)
    text = (library / "a.py").read_text()
    text = text.replace('"""Run."""', '"""Run it, twice."""').replace("# lazily", "# later")
    (library / "a.py").write_text(text.replace('"""Module a."""', '"""Module a, edited."""'))
    assert code_fingerprint(["scan2morph.a"], library) == before


def test_package_data_and_files_outside_the_package_count(library, monkeypatch):
    before = code_fingerprint(["scan2morph.a"], library)
    e_before = code_fingerprint(["scan2morph.e"], library)
    (library / "lazy_pkg" / "table.csv").write_text("a,b\n1,2\n")
    assert code_fingerprint(["scan2morph.a"], library) != before
    # a file outside the package, named for a module: missing, then there, then changed
    monkeypatch.setitem(OUTSIDE_FILES, "scan2morph.b", ("tools/bundle.js",))
    missing = code_fingerprint(["scan2morph.a"], library)
    bundle = repository_dir(library) / "tools" / "bundle.js"
    bundle.parent.mkdir()
    bundle.write_text("one")
    there = code_fingerprint(["scan2morph.a"], library)
    bundle.write_text("two!")
    assert len({missing, there, code_fingerprint(["scan2morph.a"], library)}) == 3
    assert code_fingerprint(["scan2morph.e"], library) == e_before  # e reads neither


def test_the_viewer_files_are_those_the_report_reads():
    from scan2morph.report import viewer

    repo = repository_dir(PACKAGE_DIR)
    named = {repo / p for p in OUTSIDE_FILES["scan2morph.report.viewer"]}
    assert named == {viewer.VIEWER_BUNDLE, viewer.THREE_DIR / "package.json"}


def test_dependency_versions_name_the_installed_ones():
    import h5py
    import numpy

    found = dependency_versions()
    assert found["numpy"] == numpy.__version__ and found["h5py"] == h5py.__version__
    assert "python" in found
    assert dependency_versions({"absent": ("no-such-distribution-xyz",)}).keys() == {"python"}


def test_git_state_of_a_checkout_and_none_without_one_or_without_git(tmp_path, monkeypatch):
    assert git_state(tmp_path) == {}
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    run = {"cwd": tmp_path, "check": True, "capture_output": True}
    subprocess.run(["git", "init", "-q"], **run)
    (tmp_path / "f.txt").write_text("one\n")
    subprocess.run(["git", "add", "f.txt"], **run)
    ident = ["-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(["git", *ident, "commit", "-q", "-m", "one"], **run)
    head = subprocess.run(["git", "rev-parse", "HEAD"], text=True, **run).stdout.strip()
    assert git_state(tmp_path) == {"git_commit": head, "git_dirty": False}
    (tmp_path / "f.txt").write_text("two\n")
    assert git_state(tmp_path) == {"git_commit": head, "git_dirty": True}
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))  # no git: no commit, no error
    assert git_state(tmp_path) == {}


def test_run_provenance_names_the_code_the_commit_and_the_versions(tmp_path):
    attrs = run_provenance("ab" * 32, repo=tmp_path)
    assert attrs["code_sha256"] == "ab" * 32
    assert "git_commit" not in attrs
    assert json.loads(attrs["dependencies"])["numpy"]
    if (repository_dir() / ".git").exists() and shutil.which("git"):
        assert len(run_provenance("x")["git_commit"]) == 40


def test_parses_are_kept_on_disk_and_a_bad_cache_is_only_a_cache(library, monkeypatch):
    """A second process reads the parses back (here: no parse at all, the same fingerprint);
    a changed module is parsed again; a cache file that is not JSON is ignored."""
    first = code_fingerprint(["scan2morph.a"], library)
    assert cache_file().is_file() and len(json.loads(cache_file().read_text())) >= 5
    provenance._parse.cache_clear()  # a new process
    provenance._disk_cache.cache_clear()

    def no_parse(*args, **kwargs):
        raise AssertionError("parsed again")

    with monkeypatch.context() as m:
        m.setattr(provenance.ast, "parse", no_parse)
        assert code_fingerprint(["scan2morph.a"], library) == first
        (library / "b.py").write_text("def one(x):\n    return x + 2\n")
        with pytest.raises(AssertionError, match="parsed again"):
            code_fingerprint(["scan2morph.a"], library)
    changed = code_fingerprint(["scan2morph.a"], library)
    assert changed != first
    cache_file().write_text("not json")
    provenance._parse.cache_clear()
    provenance._disk_cache.cache_clear()
    assert code_fingerprint(["scan2morph.a"], library) == changed
