"""open3d imported without its web visualiser (scan2morph.open3d_light): the import leaves dash,
plotly and IPython out, and open3d's plotly functions still work, loading them on first use.
Each check runs in a fresh interpreter (the test session may have imported open3d already)."""

from __future__ import annotations

import json
import subprocess
import sys

LEFT_OUT = ("dash", "plotly", "IPython")

CHECK = f"""
import json, sys
from scan2morph.open3d_light import PLOTLY_MODULE, open3d
o3d = open3d()
before = [m for m in {LEFT_OUT!r} if m in sys.modules]
cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector([[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]))
trace = o3d.visualization.get_plotly_fig([cloud]).data[0]
real = sys.modules[PLOTLY_MODULE]
print(json.dumps(dict(
    before=before,
    after=[m for m in {LEFT_OUT!r} if m in sys.modules],
    xyz=[list(map(float, trace.x)), list(map(float, trace.y)), list(map(float, trace.z))],
    real_module=real.__file__ is not None and not hasattr(real, "_stand_in_of"),
    swapped=o3d.visualization.draw_plotly is real.draw_plotly,
    icp=hasattr(o3d.pipelines.registration, "registration_icp"),
)))
"""


def test_open3d_without_plotly_until_used():
    out = subprocess.run(
        [sys.executable, "-c", CHECK], capture_output=True, text=True, check=True
    ).stdout
    got = json.loads(out.splitlines()[-1])
    assert got["before"] == [], got  # the import left the web viewer's libraries out
    assert got["icp"]  # the pipeline's own parts are there
    # the plotly figure of the two points, drawn by open3d's own function once asked for
    assert got["xyz"] == [[0.0, 3.0], [1.0, 4.0], [2.0, 5.0]]
    assert set(got["after"]) >= {"dash", "plotly"}
    assert got["real_module"] and got["swapped"]


def test_open3d_already_imported_is_returned_as_is():
    code = (
        "import sys, open3d\n"
        "from scan2morph.open3d_light import open3d as light\n"
        "print(light() is open3d, 'dash' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.split() == ["True", "True"]
