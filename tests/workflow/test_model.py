"""The model API (scan2morph.load_model) against the store and glTF the pipeline wrote."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

import scan2morph
from scan2morph.errors import InputError
from scan2morph.io import read_glb_targets
from scan2morph.store import paths, read_part
from tests.support.tiny_run import SUBJECT, tiny_run

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return tiny_run(tmp_path_factory, [f"results/{SUBJECT}/{SUBJECT}.h5"])


def test_model_reads_the_store(run):
    store_path = run.path("results", SUBJECT, f"{SUBJECT}.h5")
    model = scan2morph.load_model(store_path)
    store = read_part(store_path)
    assert model.subject == SUBJECT and model.labels["car"] == "car"
    np.testing.assert_array_equal(model.neutral, store[paths.neutral("vertices")])
    assert set(model.visemes) == {"car", "too"} and set(model.coordinates) == {"smile1"}
    assert model.sigma_convention == "sample" and model.provenance["format_version"]
    assert model.head_frame.shape == (4, 4) and model.texture.dtype == np.uint8
    assert model.modal_preset == "skin" and model.failed == {}  # the default physics; no take out
    with h5py.File(store_path) as h5:  # the file explains itself in any HDF5 viewer
        ds = h5[paths.mesh("car", "vertices")]
        assert ds.attrs["units"] == "mm" and "Template vertices" in ds.attrs["description"]
        assert h5[paths.modal("frequencies_hz")].attrs["units"] == "Hz"
    # a blend by label equals the morph stage's named blend (Eq. 1)
    np.testing.assert_allclose(model.blend({"car": 0.6}), store[paths.blend("car_60")], atol=1e-12)
    # an expression from its modal coordinates equals the modal stage's synthesis
    q = model.coordinates["smile1"]
    want = model.neutral + store[paths.expression("smile1", "synthesized")]
    np.testing.assert_allclose(model.expression(q), want, atol=1e-9)


def test_pca_equals_the_gltf_targets_added(run):
    """Eq. 2 through the API and through the glTF's additive morph targets agree."""
    model = scan2morph.load_model(run.path("results", SUBJECT, f"{SUBJECT}.h5"))
    base, targets = read_glb_targets(run.path("results", SUBJECT, f"{SUBJECT}.glb"))
    alphas = [1.0, -0.5][: len(model.pca_sigma)]
    weights = model.pca_weights(alphas)
    assert weights["pca_1_pos"] == pytest.approx(1 / 3) and weights["pca_1_neg"] == 0
    assert len(alphas) < 2 or weights["pca_2_neg"] == pytest.approx(0.5 / 3)
    glb = base + sum(w * (targets[name] - base) for name, w in weights.items())
    np.testing.assert_allclose(model.pca(alphas), glb, atol=1e-3)  # glTF stores float32 metres
    np.testing.assert_allclose(model.pca([]), model.pca_mean)
    # each slider's end, weight 1 (Blender's range as imported), is +-3 sigma_k
    for k in range(len(model.pca_sigma)):
        for sign in ("pos", "neg"):
            alpha = np.zeros(k + 1)
            alpha[k] = 3.0 if sign == "pos" else -3.0
            shown = targets["pca_mean"] + targets[f"pca_{k + 1}_{sign}"] - base
            np.testing.assert_allclose(model.pca(alpha), shown, atol=1e-3)


def test_bad_arguments_are_refused(run):
    model = scan2morph.load_model(run.path("results", SUBJECT, f"{SUBJECT}.h5"))
    with pytest.raises(InputError, match=r"pca: expected at most \d+ finite alphas within \+-3"):
        model.pca([5.0])
    with pytest.raises(InputError, match=r"pca: expected at most \d+ finite alphas within \+-3"):
        model.pca_weights([-3.5])
    with pytest.raises(InputError, match="expression: expected at most 10 finite coordinates"):
        model.expression(np.zeros(11))
    with pytest.raises(InputError, match="store not found"):
        scan2morph.load_model(run.path("nothing.h5"))


def test_head_meshes_of_the_workflow_are_the_store_meshes_in_the_head_frame(run, tmp_path_factory):
    """results/{subject}/meshes/head: each aligned take, model and expression in metres in the
    glTF's head frame, every face kept, the vertices without measurement filled and listed."""
    from scan2morph.io.obj import read_obj
    from scan2morph.morph.frame import apply_frame

    tiny_run(tmp_path_factory, [f"results/{SUBJECT}/meshes/head"])
    head = run.path("results", SUBJECT, "meshes", "head")
    model = scan2morph.load_model(run.path("results", SUBJECT, f"{SUBJECT}.h5"))
    store = read_part(run.path("results", SUBJECT, f"{SUBJECT}.h5"))
    frame = model.head_frame
    names = sorted(p.relative_to(head).as_posix() for p in head.rglob("*.obj"))
    assert names == sorted(
        [f"{t}.obj" for t in ("car", "neutral", "smile1", "too")]
        + [f"models/{n}.obj" for n in ("neutral", "car", "too", "pca_blend1")]
        + [f"models/{b}.obj" for b in ("car_30", "car_60", "car_90", "too_30", "too_60")]
        + ["models/too_90.obj", "models/too50_car20.obj"]
        + ["expressions/smile1_measured.obj", "expressions/smile1_synthesized.obj"]
    )
    for take in ("car", "smile1"):
        mesh = read_obj(head / f"{take}.obj")
        # the take's correspondence, as the models take it: its refined mesh
        group = paths.refined(take, store)
        aligned = np.where(
            store[group(take, "valid")][:, None], store[group(take, "vertices")], np.nan
        )
        assert not np.array_equal(aligned, store[paths.align(take, "vertices")], equal_nan=True)
        measured = np.isfinite(aligned).all(axis=1)
        assert np.array_equal(mesh["filled"], ~measured) and (~measured).sum() > 50
        assert mesh["valid"].all() and len(mesh["faces"]) == len(model.faces)
        want = apply_frame(frame, aligned[measured])
        np.testing.assert_allclose(mesh["vertices"][measured], want, rtol=0, atol=6e-7)
        assert (head / f"{take}.png").is_file() and "(m)" in (head / f"{take}.obj").read_text()[:60]
    # the models and the expressions share the neutral's texture, once a folder
    for sub in ("models", "expressions"):
        assert [p.name for p in (head / sub).glob("*.png")] == ["neutral_texture.png"]
        assert all(
            "mtllib neutral_texture.mtl" in p.read_text() for p in (head / sub).glob("*.obj")
        )
    pose = read_obj(head / "models" / "pca_blend1.obj")["vertices"]
    np.testing.assert_allclose(
        pose, apply_frame(frame, store[paths.pca_blend("pca_blend1")]), rtol=0, atol=6e-7
    )
    synth = read_obj(head / "expressions" / "smile1_synthesized.obj")["vertices"]
    np.testing.assert_allclose(
        synth, apply_frame(frame, model.expression(model.coordinates["smile1"])), atol=6e-7
    )
    neutral = read_obj(head / "models" / "neutral.obj")
    assert np.array_equal(neutral["filled"], store[paths.neutral("filled")].astype(bool))


def test_every_scanner_frame_mesh_opens_textured(run):
    """results/{subject}/meshes: each take's fit, each model and each expression (measured and
    synthesised) opens in trimesh with texture coordinates and its texture image; the models and
    the expressions share the neutral's material, once a folder (the expressions had none)."""
    import trimesh

    meshes = run.path("results", SUBJECT, "meshes")
    objs = sorted(p for sub in ("", "models", "expressions") for p in (meshes / sub).glob("*.obj"))
    assert {"smile1_measured.obj", "smile1_synthesized.obj"} <= {p.name for p in objs}
    for path in objs:
        mesh = trimesh.load(path, process=False)
        uv = getattr(mesh.visual, "uv", None)  # a mesh without a texture has ColorVisuals
        assert uv is not None and uv.shape == (len(mesh.vertices), 2), path
        assert mesh.visual.material.image is not None, path
    for sub in ("models", "expressions"):
        assert [p.name for p in (meshes / sub).glob("*.png")] == ["neutral_texture.png"]
        text = [p.read_text() for p in (meshes / sub).glob("*.obj")]
        assert all("mtllib neutral_texture.mtl" in t for t in text), sub
