"""The mesh takes' virtual camera against the truth, on every take of the default mesh subject.

For each take of synth03 (seed 2009, the default cohort's mesh subject) the view direction found
from the surface alone and with the take's clicked nose tip
(:func:`scan2morph.io.mesh_scan.view_direction`) is compared with the frontal direction of the
generator's head pose, and the face's symmetry plane found on its surface
(:func:`scan2morph.io.mesh_view.face_view`'s ``left_right``) with the head's own (the head frame's
y-z plane). Prints the angles per take (degrees) and the CPU time of one view.
``tests/unit/test_mesh_camera.py`` asserts the bound on a subset of these takes.

Usage::

    .venv/bin/python benchmarks/bench_mesh_camera.py
"""

from __future__ import annotations

import time

import numpy as np
import trimesh

from scan2morph.io.mesh_scan import view_direction
from scan2morph.io.mesh_view import face_view
from scan2morph.synth.cohort import default_takes
from scan2morph.synth.mesh_scan import make_mesh_take


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = a @ b / np.linalg.norm(a) / np.linalg.norm(b)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def main() -> None:
    print(
        f"{'take':8s} {'surface':>8s} {'+tip':>8s} {'plane':>8s} {'CPU-s':>6s}"
        "   (degrees off frontal; off the head's symmetry plane)"
    )
    worst = [0.0, 0.0, 0.0]
    for take, kind, label in default_takes():
        r = make_mesh_take("synth03", label, kind, take, 2009)
        mesh = trimesh.Trimesh(r["vertices"], r["faces"], process=False)
        frontal = -r["truth"]["pose"][:3, 2]
        t0 = time.process_time()
        surface = _angle_deg(view_direction(mesh), frontal)
        cpu = time.process_time() - t0
        clicked = _angle_deg(view_direction(mesh, r["landmarks"]), frontal)
        plane = _angle_deg(face_view(mesh).left_right, r["truth"]["pose"][:3, 0])  # kept view
        plane = min(plane, 180.0 - plane)  # the plane's normal has no sign
        worst = [max(w, x) for w, x in zip(worst, (surface, clicked, plane), strict=True)]
        print(f"{take:8s} {surface:8.2f} {clicked:8.2f} {plane:8.3f} {cpu:6.2f}")
    print(f"{'worst':8s} {worst[0]:8.2f} {worst[1]:8.2f} {worst[2]:8.3f}")


if __name__ == "__main__":
    main()
