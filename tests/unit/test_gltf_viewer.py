"""The subject's glTF as a viewer sees it: the Khronos validator finds nothing to report, and a
camera on +Z looking down -Z with +Y up (a glTF viewer's default) sees the face upright, from the
front, not mirrored, at human size; the morph targets add up to the PCA synthesis.

The file is made by the morph stage (``stages.morph.run``, then :func:`write_glb` as the stage's
writer calls it) from a face built on the real template in an arbitrary scanner frame.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pyrender
import pytest
import trimesh
from numpy.testing import assert_allclose

from scan2morph.geometry import TexturedMesh
from scan2morph.io.gltf import read_glb_frame, read_glb_targets, write_glb
from scan2morph.morph import synthesize
from scan2morph.morph.frame import apply_frame
from scan2morph.store import paths
from tests.support.morph_subject import LEFT_EYE, MOUTH, RIGHT_EYE, VISEMES
from tests.support.morph_subject import subject_glb as build_subject_glb

REPO = Path(__file__).resolve().parents[2]
VALIDATOR = REPO / "tools" / "gltf-validator"


@pytest.fixture(scope="module")
def subject_glb(tmp_path_factory):
    """The morph stage's glTF of a face seen from an arbitrary right-handed scanner frame."""
    return build_subject_glb(tmp_path_factory.mktemp("viewer"))


def _validator() -> list[str]:
    """The command that runs the Khronos glTF validator (npm ci into tools/gltf-validator when
    ``make setup`` has not yet done it)."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: the Khronos glTF validator (npm) cannot run")
    if not (VALIDATOR / "node_modules" / "gltf-validator").is_dir():
        npm = shutil.which("npm")
        assert npm, "node without npm: cannot install tools/gltf-validator (make setup)"
        subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=VALIDATOR, check=True)
    return [node, str(VALIDATOR / "validate.mjs")]


def test_khronos_validator_reports_no_error_and_no_warning(subject_glb, tmp_path):
    path = subject_glb[0]
    # also a neutral-only file (a subject without visemes) and one without texture or frame
    plain = tmp_path / "plain.glb"
    v = np.array([[0.0, 0.0, 1000.0], [10.0, 0.0, 1000.0], [0.0, 10.0, 1000.0]])
    write_glb(plain, TexturedMesh(v, np.array([[0, 1, 2]])), {"up": v + [0.0, 0.0, 1.0]})
    out = subprocess.run(
        [*_validator(), str(path), str(plain)], capture_output=True, text=True, check=True
    )
    reports = json.loads(out.stdout)
    for report in reports:
        issues = report["issues"]
        messages = [f"{m['code']}: {m['message']}" for m in issues["messages"]]
        assert (issues["numErrors"], issues["numWarnings"]) == (0, 0), messages
    info = reports[0]["info"]
    assert info["version"] == "2.0" and info["hasMorphTargets"] and info["hasTextures"]
    assert info["drawCallCount"] == 1 and info["totalTriangleCount"] == len(
        subject_glb[1].files["faces"]
    )


def _render(path: Path, distance: float = 0.5, yfov: float = np.radians(40.0), size: int = 400):
    """Render a glb as a default glTF viewer camera would: on +Z, looking down -Z, +Y up."""
    scene = pyrender.Scene.from_trimesh_scene(
        trimesh.load(path, process=False), bg_color=[1.0, 1.0, 1.0, 1.0], ambient_light=[1.0] * 3
    )
    pose = np.eye(4)
    pose[2, 3] = distance
    scene.add(pyrender.PerspectiveCamera(yfov=yfov, aspectRatio=1.0), pose=pose)
    renderer = pyrender.OffscreenRenderer(size, size)
    try:
        color, depth = renderer.render(scene, flags=pyrender.RenderFlags.FLAT)
    finally:
        renderer.delete()
    return color, depth, 2 * distance * np.tan(yfov / 2) / size  # metres per pixel at z = 0


def _blob(image: np.ndarray, rgb) -> tuple[float, float, int]:
    """Centroid (row, column) and size of the pixels close to a colour."""
    near = np.all(np.abs(image.astype(int) - rgb) < 40, axis=-1)
    rows, cols = np.nonzero(near)
    return (
        float(rows.mean()) if len(rows) else np.nan,
        float(cols.mean()) if len(cols) else np.nan,
        len(rows),
    )


def test_viewer_sees_the_face_upright_from_the_front_at_human_size(subject_glb):
    path = subject_glb[0]
    image, depth, metre_per_px = _render(path)
    r_row, r_col, r_n = _blob(image, RIGHT_EYE)
    l_row, l_col, l_n = _blob(image, LEFT_EYE)
    m_row, m_col, m_n = _blob(image, MOUTH)
    assert min(r_n, l_n, m_n) > 50  # all three are seen: the camera looks at the front
    assert m_row - 0.5 * (r_row + l_row) > 60  # eyes above the mouth (image rows grow down)
    assert l_col - r_col > 60  # the subject's left eye on the viewer's right: not mirrored
    assert abs(m_col - 0.5 * (r_col + l_col)) < 10
    face = depth > 0
    rows, cols = np.nonzero(face)
    width_m = (cols.max() - cols.min() + 1) * metre_per_px
    height_m = (rows.max() - rows.min() + 1) * metre_per_px
    # human size, metres (the template covers the face inside the jaw line, without the ears:
    # the synthetic cohort's fitted faces measure 0.11 m x 0.17 m)
    assert 0.08 < width_m < 0.2 and 0.12 < height_m < 0.25
    assert 0.1 < face.mean() < 0.6  # a sensible part of the view
    # centred on the origin between the eyes: the eyes sit on the image's middle row
    assert abs(0.5 * (r_row + l_row) - image.shape[0] / 2) < 15
    assert abs(0.5 * (r_col + l_col) - image.shape[1] / 2) < 5


def test_file_frame_is_the_stored_head_frame_and_targets_add(subject_glb):
    path, part, sub, data = subject_glb
    frame = part.datasets[paths.neutral("head_frame")]
    assert_allclose(read_glb_frame(path), frame, rtol=0, atol=0)
    r = frame[:3, :3] / 1e-3
    assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) > 0
    base, targets = read_glb_targets(path, frame="gltf")
    named = sub.named
    eyes = base[[named[n] for n in ("eye_r_outer", "eye_r_inner", "eye_l_inner", "eye_l_outer")]]
    assert_allclose(eyes.mean(axis=0), 0.0, atol=1e-7)  # origin between the eyes
    mouth = base[[named["mouth_r"], named["mouth_l"]]].mean(axis=0)
    assert mouth[1] < -0.05 and abs(mouth[0]) < 1e-6  # the mouth below the eyes (+Y up)
    assert base[named["nose_tip"], 2] > 0.01  # the nose towards the viewer (+Z)
    # source-frame read back: the neutral and the viseme models, mm
    src_base, src = read_glb_targets(path)
    assert_allclose(src_base, data[paths.neutral("vertices")], atol=1e-4)
    assert_allclose(src["car"], data[paths.viseme("car", "model")], atol=1e-4)
    # layout: one target per viseme (model - neutral), pca_mean, two per component (+-3 sigma_k
    # e_k), their signed sigmas in the extras
    k = len(part.datasets[paths.pca("eigenvalues")])
    pairs = [f"pca_{i + 1}_{s}" for i in range(k) for s in ("pos", "neg")]
    assert list(targets) == [*VISEMES, "pca_mean", *pairs]
    extras = pygltflib.GLTF2.load(str(path)).meshes[0].extras
    assert extras["targetSigmas"] == {n: (3.0 if n.endswith("pos") else -3.0) for n in pairs}
    assert "-3 sigma_2 e_2" in extras["targetNotes"]["pca_2_neg"]
    # a viewer's weights 1 on pca_mean and |alpha_k| / 3 on pca_k_pos or pca_k_neg give the PCA
    # synthesis (Eq. 2)
    from scan2morph.morph.pca import PCAModel

    names = ("mean", "components", "eigenvalues", "cr", "ccr", "coefficients")
    model = PCAModel(
        **{n: part.datasets[paths.pca(n)] for n in names},
        names=tuple(part.datasets[paths.pca("takes")]),
        sigma=part.datasets[paths.pca("sigma")],
        sigma_convention=str(part.datasets[paths.pca("sigma_convention")]),
    )
    alpha = np.array([1.0, -1.0])
    weights = {"pca_mean": 1.0, "pca_1_pos": alpha[0] / 3, "pca_2_neg": -alpha[1] / 3}
    shown = base + sum(w * (targets[n] - base) for n, w in weights.items())
    assert_allclose(shown, apply_frame(frame, synthesize(model, alpha)), rtol=0, atol=1e-6)
    assert_allclose(model.sigma, np.std(model.coefficients, axis=0, ddof=1), rtol=1e-12)


def test_report_viewer_gives_one_slider_in_sigmas_per_component(subject_glb):
    """The report's viewer pairs pca_k_pos/pca_k_neg into one pca_k slider over -3..3 sigma_k
    (value a: weight a/3 on pos, -a/3 on neg); a file from before the pair layout keeps its
    single pca_k target as a -3..3 weight."""
    from scan2morph.report.viewer import glb_target_names, semantic_sliders

    names, notes, sigmas = glb_target_names(subject_glb[0])
    sliders = semantic_sliders(names, notes, sigmas)
    assert [s["name"] for s in sliders] == [*VISEMES, "pca_mean", "pca_1", "pca_2", "pca_3"]
    for s in sliders[4:]:
        k = s["name"].split("_")[1]
        assert (names[s["index"]], names[s["negative"]]) == (f"pca_{k}_pos", f"pca_{k}_neg")
        assert (s["min"], s["max"], s["per"]) == (-3.0, 3.0, 3.0)
    assert all((s["min"], s["max"], s["negative"]) == (0.0, 1.0, None) for s in sliders[:4])
    old = semantic_sliders(["car", "pca_mean", "pca_1"], {}, {})
    assert [(s["name"], s["min"], s["max"], s["per"]) for s in old] == [
        ("car", 0.0, 1.0, 1.0),
        ("pca_mean", 0.0, 1.0, 1.0),
        ("pca_1", -3.0, 3.0, 1.0),
    ]
