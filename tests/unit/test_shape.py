"""The shape check (tools/check_shape.py): the library passes it, with its allowlist, and it
finds each kind of offence in small made-up modules."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tools" / "check_shape.py"


def _load():
    spec = importlib.util.spec_from_file_location("check_shape", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["check_shape"] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


shape = _load()


def _keys(sources: dict[str, str]) -> list[str]:
    return [o.key for o in shape.check_sources(sources)]


def _function(name: str, lines: int, params: str = "") -> str:
    body = "".join(f"    x{k} = {k}\n" for k in range(lines - 2))
    return f"def {name}({params}):\n    '''doc'''\n{body}"


def test_the_library_keeps_its_shape():
    """The script's own run on the repository: exit 0, nothing printed (every offence left is
    on the allowlist, and no entry there is stale)."""
    run = subprocess.run(
        [sys.executable, str(SCRIPT)], capture_output=True, text=True, cwd=ROOT, check=False
    )
    assert run.returncode == 0 and run.stdout == "", run.stdout + run.stderr


def test_a_long_function_and_a_long_module():
    """101 lines is one too many for a function, 100 is not; 601 for a module."""
    src = _function("ok", 100) + _function("too_long", 101)
    offences = shape.check_sources({"src/scan2morph/a.py": src})
    assert [o.key for o in offences] == ["src/scan2morph/a.py:too_long"]
    assert "101 lines" in offences[0].message
    nested = "class C:\n    def m(self):\n" + "".join(
        "        " + line + "\n" for line in _function("inner", 101).splitlines()
    )
    assert _keys({"src/scan2morph/b.py": nested}) == [
        "src/scan2morph/b.py:C.m",
        "src/scan2morph/b.py:C.m.inner",
    ]
    long_module = "x = 1\n" * 601
    assert _keys({"src/scan2morph/c.py": long_module}) == ["src/scan2morph/c.py:<module>"]
    assert _keys({"src/scan2morph/c.py": "x = 1\n" * 600}) == []


def test_public_functions_with_more_than_eight_parameters():
    """Nine parameters offend in a public function or method (self not counted, *args and
    keyword-only ones counted), not in a private one."""
    src = "\n".join(
        [
            "def eight(a, b, c, d, e, f, g, h): pass",
            "def nine(a, b, c, d, e, f, g, *, h, i=1): pass",
            "def star(a, *args, **kwargs): pass",
            "def _private(a, b, c, d, e, f, g, h, i): pass",
            "class Public:",
            "    def __init__(self, a, b, c, d, e, f, g, h, i): pass",
            "    def method(self, a, b, c, d, e, f, g, h): pass",
            "    def _hidden(self, a, b, c, d, e, f, g, h, i): pass",
            "class _Private:",
            "    def method(self, a, b, c, d, e, f, g, h, i): pass",
        ]
    )
    assert _keys({"src/scan2morph/p.py": src}) == [
        "src/scan2morph/p.py:Public.__init__(params)",
        "src/scan2morph/p.py:nine(params)",
    ]


def test_an_import_against_the_layers():
    """``scan`` may import ``io`` and the base (``geometry``, ``store.paths``), not ``template``
    (a later layer), not even lazily inside a function; ``from package import module`` is an
    import of the module."""
    sources = {
        "src/scan2morph/scan/a.py": (
            "from scan2morph.io import take\n"
            "from scan2morph.geometry import unique_edges\n"
            "from scan2morph.store import paths\n"
            "def f():\n"
            "    from scan2morph.template import sample\n"
        ),
        "src/scan2morph/io/take.py": "",
        "src/scan2morph/geometry.py": "",
        "src/scan2morph/store/paths.py": "import scan2morph.errors\n",
        "src/scan2morph/errors.py": "",
        "src/scan2morph/template/sample.py": "from scan2morph.scan import a\n",
    }
    offences = shape.check_sources(sources)
    assert [o.key for o in offences] == [
        "src/scan2morph/scan/a.py:import scan2morph.template.sample"
    ]
    assert "'scan' imports from the later layer 'template'" in offences[0].message
    assert shape.layer_of("scan2morph.store.paths") == 0 == shape.layer_of("scan2morph.tol")
    assert shape.layer_of("scan2morph.stages.align") > shape.layer_of("scan2morph.morph.pca")


def test_an_import_cycle():
    """Three modules importing in a ring are one cycle, named from its first module; a lazy
    import inside a function closes no cycle."""
    ring = {
        "src/scan2morph/motion/a.py": "from scan2morph.motion import b\n",
        "src/scan2morph/motion/b.py": "import scan2morph.motion.c\n",
        "src/scan2morph/motion/c.py": "from scan2morph.motion.a import x\n",
    }
    offences = shape.check_sources(ring)
    assert [o.key for o in offences] == ["src/scan2morph/motion/a.py:<cycle>"]
    assert offences[0].message == (
        "import cycle: scan2morph.motion.a -> scan2morph.motion.b -> scan2morph.motion.c "
        "-> scan2morph.motion.a"
    )
    lazy = ring | {
        "src/scan2morph/motion/c.py": "def f():\n    from scan2morph.motion.a import x\n"
    }
    assert _keys(lazy) == []


def test_the_allowlist_hides_known_offences_and_reports_stale_entries():
    src = _function("too_long", 120)
    offences = shape.check_sources({"src/scan2morph/a.py": src})
    entries = shape.read_allowlist(
        "# a comment\n\n"
        "src/scan2morph/a.py:too_long: owned elsewhere\n"
        "src/scan2morph/a.py:gone: fixed last week\n"
    )
    assert shape.apply_allowlist(offences, entries, "list.txt") == [
        "list.txt:4: stale entry src/scan2morph/a.py:gone: no such offence any more (remove it)"
    ]
    assert shape.apply_allowlist(offences, {}, "list.txt") == [
        "src/scan2morph/a.py:too_long: 120 lines (at most 100)"
    ]
    with pytest.raises(ValueError, match="line 1: expected 'path:subject: reason'"):
        shape.read_allowlist("src/scan2morph/a.py:too_long\n")


def test_the_script_fails_with_one_line_per_offence(tmp_path):
    """Run as a script on a made-up tree: exit 1, one line per offence and stale entry."""
    pkg = tmp_path / "src" / "scan2morph"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "io.py").write_text("from scan2morph.stages import run\n")
    (pkg / "stages.py").write_text(_function("run", 150))
    allow = tmp_path / "allow.txt"
    allow.write_text("src/scan2morph/io.py:old: was fixed\n")
    run = subprocess.run(
        [sys.executable, str(SCRIPT), "--root", str(tmp_path), "--allowlist", str(allow)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 1
    assert run.stdout.splitlines() == [
        "src/scan2morph/io.py:import scan2morph.stages: layer 'io' imports from the later "
        "layer 'stages'",
        "src/scan2morph/stages.py:run: 150 lines (at most 100)",
        "allow.txt:1: stale entry src/scan2morph/io.py:old: no such offence any more (remove it)",
    ]
