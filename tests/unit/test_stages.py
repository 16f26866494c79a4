"""The stage contract: each stage's parameters from its config sections, the datasets it owns,
and the sweep's stage table derived from the stage modules."""

from __future__ import annotations

import copy
import dataclasses
import importlib
import inspect
from pathlib import Path

import numpy as np
import pytest

from scan2morph.align import IcpParams
from scan2morph.errors import InputError
from scan2morph.sheet import validate_config
from scan2morph.stages import Part, Subject, Take, align, fit, modal, morph, motion
from scan2morph.store import paths, read_part
from scan2morph.sweep import SECTION_STAGE, STAGES
from scan2morph.template import FitRules, load_template
from tests.support.configs import repo_config
from tests.support.tiny_run import SUBJECT, TAKES, tiny_run

REPO = Path(__file__).resolve().parents[2]
CONFIG = repo_config()
VALIDATED = validate_config(copy.deepcopy(CONFIG), REPO / "schemas" / "config.schema.yaml")


def test_subject_takes_by_kind_in_sheet_order():
    s = Subject("s1", {"n": "neutral", "b": "viseme", "x": "expression", "a": "viseme"}, {})
    assert (s.neutral, s.visemes, s.expressions) == ("n", ["b", "a"], ["x"])
    assert s.source("a") == "s1/a"
    with pytest.raises(InputError, match=r"s2: takes: expected exactly one neutral take, got \[\]"):
        _ = Subject("s2", {"a": "viseme"}, {}).neutral
    with pytest.raises(InputError, match=r"got \['n', 'm'\]"):
        _ = Subject("s3", {"n": "neutral", "m": "neutral"}, {}).neutral


def test_take_of_a_subject_carries_its_ids_and_inputs():
    s = Subject("s1", {"n": "neutral", "b": "viseme"}, {"n": "neutral", "b": "car"})
    take = Take.of(s, "b", data={"/x": np.zeros(2)}, row={"modality": "rgbd"})
    assert (take.subject, take.take, take.kind, take.label, take.neutral) == (
        "s1",
        "b",
        "viseme",
        "car",
        "n",
    )
    assert take.source == "s1/b" and take.row["modality"] == "rgbd" and dict(take.files) == {}
    with pytest.raises(InputError, match=r"s1: take q: not one of the subject's takes"):
        Take.of(s, "q")


#: Every stage module and its level (the run's shape).
STAGE_LEVELS = {
    **dict.fromkeys(
        ("check", "ingest", "repair", "landmarks", "fit", "align", "refine", "synth"), "take"
    ),
    **dict.fromkeys(
        ("motion", "motion_noise", "morph", "modal", "store", "accuracy", "report"), "subject"
    ),
}
RUN_SHAPES = {
    "take": ["template", "take", "params"],
    "subject": ["template", "subject", "data", "params"],
}


@pytest.mark.parametrize("name", sorted(STAGE_LEVELS))
def test_every_stage_has_the_contract_shape(name):
    module = importlib.import_module(f"scan2morph.stages.{name}")
    assert dataclasses.is_dataclass(module.Params) and module.Params.__dataclass_params__.frozen
    assert list(inspect.signature(module.Params.from_config).parameters) == ["config"]
    assert list(inspect.signature(module.run).parameters) == RUN_SHAPES[STAGE_LEVELS[name]]
    assert inspect.signature(module.run).return_annotation in ("Part", Part)
    # the whole (validated) config is enough, whatever sections the stage reads
    params = module.Params.from_config(VALIDATED)
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(params, next(iter(vars(params)), "x"), None)


def test_fiducial_set_of_each_kind():
    section = CONFIG["template"]
    params = fit.Params.from_config(CONFIG)
    assert params.fiducial_set("viseme") == section["fiducials"]["viseme"]
    # a kind the config does not name gets the closed-mouth set
    assert fit.Params({}, FitRules()).fiducial_set("expression") == "closed"
    assert params.rules.levels == 1 and params.rules.max_slope_deg == section["max_slope_deg"]


def test_the_stores_config_hash_leaves_out_what_never_reaches_a_store():
    """The report page's settings, the sweep table's path and the sheet's path reach no store:
    changing them (moving the sheet) leaves the store's parameters (and so its fingerprint: it
    is not rebuilt, nor is any stage after it) as they were; a key a stage reads changes them."""
    from scan2morph.jobs import config_sha256
    from scan2morph.stages import store

    base = store.Params.from_config(CONFIG)
    report = CONFIG | {"report": CONFIG["report"] | {"thumbnail_px": 120}}
    swept = CONFIG | {"sweeps": "my_sweeps.tsv"}
    moved = CONFIG | {"subjects": "/elsewhere/subjects.tsv"}
    assert store.Params.from_config(report) == base == store.Params.from_config(swept)
    assert store.Params.from_config(moved) == base
    smoother = CONFIG | {"smoothing": CONFIG["smoothing"] | {"iterations": 10}}
    assert store.Params.from_config(smoother) != base
    kept = {k: v for k, v in CONFIG.items() if k not in ("report", "sweeps", "subjects")}
    assert base.config_sha256 == config_sha256(kept)
    assert config_sha256(CONFIG, ["sweeps"]) != config_sha256(CONFIG)


def test_params_from_config_sections():
    a = align.Params.from_config(CONFIG)
    assert a.point_pairs == CONFIG["align"]["point_pairs"]
    assert a.grow_into == CONFIG["align"]["grow_into"]
    assert a.icp == IcpParams(**CONFIG["align"]["icp"]) and a.icp.kernel_k_mm == 0.3
    bad = CONFIG | {"align": CONFIG["align"] | {"icp": {"robust_kernel": "cauchy"}}}
    with pytest.raises(InputError, match=r"^config: align.icp: robust_kernel must be one of"):
        align.Params.from_config(bad)
    m = motion.Params.from_config({k: v for k, v in CONFIG.items() if k != "refine"})
    assert (m.radius_mm, m.w, m.iterations) == (20.0, 0.1, 30)  # the paper's values
    assert m.include_failed is False and m.refined is False
    m = motion.Params.from_config(CONFIG)
    assert (m.refined, m.relief, m.expression_iterations) == (True, 0.5, 10)
    data = {
        paths.refine("t", "vertices"): np.zeros((3, 3)),
        paths.refine("t", "valid"): np.ones(3, bool),
        paths.refine("t", "confidence"): np.array([0.2, 0.9, 0.0]),
    }
    mesh = motion.aligned_mesh(data, "t", "s", refined=True)
    np.testing.assert_array_equal(mesh.confidence, [0.2, 0.9, 0.0])
    p = modal.Params.from_config(CONFIG)
    assert p.modal.thickness_mm == 1.0 and p.modal.threads == 1
    assert p.with_threads(2).modal.threads == 2 and p.with_threads(2).levels == p.levels


def test_semantic_takes_first_take_of_each_label():
    s = Subject(
        "s",
        {"n": "neutral", "sm1": "expression", "sad1": "expression", "sm2": "expression"},
        {"n": "neutral", "sm1": "smile", "sad1": "sad", "sm2": "smile"},
    )
    assert modal.semantic_takes(s, ["sad", "smile", "anger"]) == ["sad1", "sm1"]


def test_sweep_stage_table_is_derived_from_the_stage_modules():
    assert STAGES == (
        "repair",
        "landmarks",
        "fit",
        "align",
        "refine",
        "consensus",
        "motion",
        "motion_noise",
    )
    assert SECTION_STAGE == {
        "repair": "repair",
        "landmarks": "landmarks",
        "template": "landmarks",  # the fold test of a detected take's points (unfold)
        "align": "align",
        "refine": "refine",
        "mask": "motion",
        "smoothing": "motion",
        "quality": "consensus",
        "motion_noise": "motion_noise",
    }


@pytest.mark.slow
def test_each_part_holds_the_datasets_its_stage_owns(tmp_path_factory):
    """Every dataset of a stage's part is written by that stage (paths.DATASETS), or passed on
    from an earlier one; and every dataset of the store comes from the part of its stage."""
    takes = [t["take"] for t in TAKES]
    stages = ("ingest", "repair", "landmarks", "fit", "align", "refine")
    parts = {f"takes/{t}/{s}.h5": s for t in takes for s in stages}
    # (the consensus part holds datasets only for takes refined by their shape: none here)
    parts |= {f"{s}.h5": s for s in ("motion", "motion_noise", "morph", "modal")}
    parts[f"{SUBJECT}.h5"] = "store"
    parts["template.h5"] = "fit"
    run = tiny_run(tmp_path_factory, [f"results/{SUBJECT}/{SUBJECT}.h5"])
    owner = {}
    for rel, stage in parts.items():
        keys = read_part(run.path("results", SUBJECT, rel)).keys()
        later = paths.written_by(paths.STAGES[paths.STAGES.index(stage) + 1 :])
        assert not [k for k in keys if later.match(k)], rel
        own = paths.written_by([stage])
        assert any(own.match(k) for k in keys), rel
        owner |= {k: stage for k in keys if own.match(k)}
    store = read_part(run.path("results", SUBJECT, f"{SUBJECT}.h5"))
    for key in store:
        assert owner.get(key) is not None and paths.written_by([owner[key]]).match(key), key


@pytest.mark.slow
def test_a_take_that_failed_its_alignment_gate_is_left_out_of_the_models(tmp_path_factory):
    """motion.run models only the takes whose /takes/{take}/align/ok holds (unless
    quality.include_failed_takes); the stages after it (morph) work on what it modelled."""
    run = tiny_run(tmp_path_factory, [f"results/{SUBJECT}/{SUBJECT}.h5"])
    takes = [t["take"] for t in TAKES]
    data = {}
    for take in takes:
        for stage in ("repair", "fit", "align"):
            data |= read_part(run.path("results", SUBJECT, "takes", take, f"{stage}.h5"))
    data[paths.align("car", "ok")] = np.bool_(False)
    subject = Subject(
        SUBJECT, {t["take"]: t["kind"] for t in TAKES}, {t["take"]: t["label"] for t in TAKES}
    )
    template = load_template(run.path("resources", "template.npz"))
    c = {k: v for k, v in CONFIG.items() if k != "refine"}
    strict = motion.Params.from_config(c)
    out = motion.run(template, subject, data, strict).datasets
    assert paths.viseme("car", "model") not in out and paths.viseme("too", "model") in out
    assert paths.expression("smile1", "displacement") in out
    pca = morph.run(template, subject, data | out, morph.Params.from_config(c)).datasets
    assert list(pca[paths.pca("takes")]) == ["neutral", "too"]
    lenient = motion.Params.from_config(c | {"quality": {"include_failed_takes": True}})
    assert paths.viseme("car", "model") in motion.run(template, subject, data, lenient).datasets
