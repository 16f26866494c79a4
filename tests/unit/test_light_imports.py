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


def _python(code: str) -> str:
    """What ``code`` prints, run in a fresh interpreter."""
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout


#: Modules that the stages which neither read stereo pairs nor write glTF do not import either:
#: scan2morph.scan and scan2morph.io import a module when one of its names is first used
#: (scan2morph.lazy), and the stages import the template for its type only (repair needs none).
UNUSED = ("scan2morph.scan.stereo", "scan2morph.io.gltf", "pygltflib", "scan2morph.template")
NOT_IMPORTED = {
    "ingest": HEAVY,
    "repair": HEAVY + UNUSED,
    "fit": HEAVY + UNUSED[:3],
    "align": HEAVY + UNUSED[:3],
    "refine": HEAVY,
}


@pytest.mark.parametrize("stage", list(NOT_IMPORTED))
def test_take_stage_imports_are_light(stage):
    code = (
        "import sys\n"
        f"import scan2morph.stages.{stage}, scan2morph.stages.failure, scan2morph.store\n"
        f"print(' '.join(m for m in {NOT_IMPORTED[stage]!r} if m in sys.modules))"
    )
    out = _python(code)
    assert out.split() == [], f"scan2morph.stages.{stage} imports {out.split()}"


def test_a_lazy_package_gives_its_names_on_first_use():
    code = (
        "import sys\n"
        "import scan2morph.scan as scan\n"
        "before = 'scan2morph.scan.stereo' in sys.modules\n"
        "from scan2morph.scan import DEFAULT_STEREO\n"
        "from scan2morph.scan.stereo import DEFAULT_STEREO as direct\n"
        "print(before, DEFAULT_STEREO is direct, 'DEFAULT_STEREO' in vars(scan),\n"
        "      'reconstruct_stereo' in dir(scan), 'reconstruct_stereo' in scan.__all__)\n"
        "try:\n"
        "    scan.no_such_name\n"
        "except AttributeError as error:\n"
        "    print(error)\n"
    )
    out = _python(code).splitlines()
    assert out[0].split() == ["False", "True", "True", "True", "True"]
    assert out[1] == "module 'scan2morph.scan' has no attribute 'no_such_name'"


def test_carrying_stable_points_needs_no_open3d():
    """A detected take's second pass aligns it to its neutral without open3d (1.3 s to import in
    a take's job): the carried points' ICP is the project's own."""
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from scan2morph.align.carry import carry_stable\n"
        "y, x = np.mgrid[0:160, 0:160].astype(float)\n"
        "z = 600.0 + ((x - 80.0) ** 2 + (y - 80.0) ** 2) / 80.0\n"
        "xyz = np.stack([x - 80.0, y - 80.0, z], axis=-1)\n"
        "points = np.column_stack([np.linspace(40, 120, 68), np.linspace(50, 110, 68)])\n"
        "got = carry_stable(xyz, points, xyz, points, (28, 37, 40, 43, 46), 'x')\n"
        "print(bool(got.carried.all()), 'open3d' in sys.modules)"
    )
    assert _python(code).split() == ["True", "False"]
