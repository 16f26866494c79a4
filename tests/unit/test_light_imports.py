"""A take's stage jobs import no table, plotting or rendering library (issue #35: every job is
a process of its own, and an import it does not need is paid by every take). Each stage module
is imported in a fresh interpreter, as the workflow's adapter script imports it."""

from __future__ import annotations

import subprocess
import sys

import pytest

#: Libraries a take's stages do not need at import: pandas (sheets and tables), matplotlib
#: (figures), pyrender/trimesh (rendering: a mesh take's ingest imports them when it renders),
#: open3d (imported by the functions that align or ray-cast) and its web viewer.
HEAVY = ("pandas", "matplotlib", "pyrender", "trimesh", "open3d", "dash", "plotly")


@pytest.mark.parametrize("stage", ["ingest", "repair", "fit", "align", "refine"])
def test_take_stage_imports_are_light(stage):
    code = (
        "import sys\n"
        f"import scan2morph.stages.{stage}, scan2morph.stages.failure, scan2morph.store\n"
        f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.split() == [], f"scan2morph.stages.{stage} imports {out.split()}"
