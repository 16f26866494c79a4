"""``tools/check_config.py``: a config file refused in one line naming it (the bad-input
audit's F5, F6: a missing file ended in Snakemake's traceback, a YAML error named neither the
file nor the line, and a section given twice silently kept its last value)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.support.configs import REPO

TOOL = REPO / "tools" / "check_config.py"


def _check(path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(TOOL), str(path)], capture_output=True, text=True, check=False
    )


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (None, "{path}: config file not found (expected a YAML file"),
        (
            "modal:\n  modes: 10\nmodal:\n  preset: paper\n",
            "{path}: line 3: key 'modal' given twice (first on line 1): keep one value",
        ),
        (
            "modal:\n  modes: 10\n  modes: 20\n",
            "{path}: line 3: key 'modes' given twice (first on line 2)",
        ),
        ("modal:\n\tmodes: 10\n", "{path}: line 2: found a tab (YAML indents with spaces)"),
        ("- modal\n", "{path}: expected a mapping of config sections, got list"),
    ],
)
def test_a_bad_config_file_is_one_line_naming_it(tmp_path, text, message):
    path = tmp_path / "my.yaml"
    if text is not None:
        path.write_text(text)
    done = _check(path)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: " + message.format(path=path))


def test_the_default_config_and_an_override_pass(tmp_path):
    assert _check(REPO / "config" / "config.yaml").returncode == 0
    (tmp_path / "ok.yaml").write_text("modal: {modes: 10}\n")
    done = _check(tmp_path / "ok.yaml")
    assert done.returncode == 0 and done.stderr == ""
