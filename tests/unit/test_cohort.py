"""The cohort summary (scan2morph.report.cohort): analytic stores, then the tiny run's rule."""

from __future__ import annotations

import json
import re

import cv2
import h5py
import numpy as np
import pandas as pd
import pytest

from scan2morph.errors import InputError
from scan2morph.report import cohort as cohort_module
from scan2morph.report import (
    cohort_table,
    motion_rms,
    plot_cohort,
    subject_summary,
    write_cohort_summary,
)
from scan2morph.store import merge_parts, paths, write_part
from scan2morph.tables import read_dictionary
from tests.support.tiny_run import SUBJECT, tiny_run

V = 50


def _store(tmp_path, subject, takes, motions, ccr, freqs, noise=None):
    """A store with the datasets the summary reads: takes (kind, label), viseme motion, PCA CCR,
    modal frequencies, and optionally the click-noise error bar (take -> relative)."""
    part = tmp_path / f"{subject}_part.h5"
    data = {paths.viseme(t, "motion"): m for t, m in motions.items()}
    if noise:
        data[paths.motion_noise("takes")] = np.array(list(noise), dtype=object)
        data[paths.motion_noise("relative")] = np.array(list(noise.values()))
    data |= {
        paths.pca("ccr"): np.asarray(ccr, float),
        paths.modal("frequencies_hz"): np.asarray(freqs, float),
    }
    data |= {paths.landmarks(t): np.zeros((68, 2)) for t in takes}
    attrs = {paths.take(t): {"kind": k, "label": lab} for t, (k, lab) in takes.items()}
    write_part(part, data, attrs)
    path = tmp_path / f"{subject}.h5"
    merge_parts(path, [part], subject, "0" * 64)
    return path


@pytest.fixture
def stores(tmp_path):
    rng = np.random.default_rng(3)
    alice_motion = {
        "car": np.tile([3.0, 4.0, 0.0], (V, 1)),  # |m| = 5 everywhere
        "too1": np.tile([0.0, 0.0, 1.0], (V, 1)),
        "too2": np.tile([0.0, 0.0, 3.0], (V, 1)),
    }
    alice_motion["too2"][:5] = np.nan  # rows without data are left out
    alice = _store(
        tmp_path,
        "alice",
        {
            "neutral": ("neutral", "neutral"),
            "car": ("viseme", "car"),
            "too1": ("viseme", "too"),
            "too2": ("viseme", "too"),
            "smile1": ("expression", "smile"),
        },
        alice_motion,
        [0.5, 0.8, 0.95, 1.0],
        [12.5, 20.0],
        noise={"too2": 0.3, "car": 0.1, "too1": 0.2},
    )
    bob_car = rng.normal(size=(V, 3))
    bob = _store(
        tmp_path,
        "bob",
        {"neutral": ("neutral", "neutral"), "car": ("viseme", "car")},
        {"car": bob_car},
        [0.9, 1.0],
        [30.0],
    )
    return alice, bob, bob_car


def _motion_entry(material, normal, tangential, ideal):
    return {
        "material_relative_error": material,
        "material_rms_mm": 10.0,
        "material_rms_error_mm": 10.0 * material,
        "material_normal_rms_error_mm": normal,
        "material_tangential_rms_error_mm": tangential,
        "relative_error": ideal,
    }


#: accuracy.json takes of alice: two "too" takes (the label's columns are their means), one
#: viseme with a null, the expression's material entry.
ALICE_TAKES = {
    "car": {"motion": _motion_entry(0.4, 0.3, 3.9, 0.2)},
    "too1": {"motion": _motion_entry(0.9, 0.2, 2.0, 0.1)},
    "too2": {"motion": _motion_entry(0.7, 0.4, 1.0, None)},
    "smile1": {
        "expression": {
            "material_relative_error": 1.5,
            "material_rms_mm": 2.0,
            "material_rms_error_mm": 3.0,
            "material_normal_rms_error_mm": 0.8,
            "material_tangential_rms_error_mm": 2.9,
        }
    },
    "neutral": {"mesh": {"rms_mm": 0.1}},
}


def test_subject_summary_matches_analytic_values(stores):
    alice, bob, bob_car = stores
    acc = {
        "summary": {"mesh_rms_mm_max": 0.5, "align_rotation_deg_max": 0.25, "none": None},
        "takes": ALICE_TAKES,
    }
    s = subject_summary(alice, acc)
    assert s.row == {
        "subject": "alice",
        "n_takes": 5,
        "n_visemes": 3,
        "n_expressions": 1,
        "left_out": pytest.approx(float("nan"), nan_ok=True),
        "material_relative_error_viseme_car": 0.4,
        "material_relative_error_viseme_too": pytest.approx(0.8),
        "material_rms_error_mm_viseme_car": 4.0,
        "material_rms_error_mm_viseme_too": pytest.approx(8.0),
        "material_normal_rms_error_mm_viseme_car": 0.3,
        "material_normal_rms_error_mm_viseme_too": pytest.approx(0.3),
        "material_tangential_rms_error_mm_viseme_car": 3.9,
        "material_tangential_rms_error_mm_viseme_too": pytest.approx(1.5),
        "ideal_relative_error_viseme_car": 0.2,
        "ideal_relative_error_viseme_too": 0.1,  # the null of too2 is left out
        "material_relative_error_expression_smile": 1.5,
        "material_rms_error_mm_expression_smile": 3.0,
        "material_normal_rms_error_mm_expression_smile": 0.8,
        "material_tangential_rms_error_mm_expression_smile": 2.9,
        "motion_rms_all_mm_car": 5.0,
        "motion_rms_all_mm_too": 2.0,  # mean of 1 and 3 over the two takes of the label
        "noise_relative_unmasked_car": 0.1,
        "noise_relative_unmasked_too": pytest.approx(0.25),
        "ccr_1": 0.5,
        "ccr_2": 0.8,
        "ccr_3": 0.95,
        "modal_f1_hz": 12.5,
        "mesh_rms_mm_max": 0.5,
        "align_rotation_deg_max": 0.25,
        "none": pytest.approx(np.nan, nan_ok=True),
    }
    np.testing.assert_array_equal(s.ccr, [0.5, 0.8, 0.95, 1.0])
    b = subject_summary(bob).row
    assert b["motion_rms_all_mm_car"] == pytest.approx(np.sqrt((bob_car**2).sum() / V), rel=1e-12)
    assert np.isnan(b["ccr_3"]) and b["ccr_2"] == 1.0 and b["modal_f1_hz"] == 30.0


def test_cohort_table_fills_missing_columns_with_nan(stores):
    alice, bob, _ = stores
    table = cohort_table(
        [subject_summary(bob), subject_summary(alice, {"summary": {"mesh_rms_mm_max": 0.5}})]
    )
    assert list(table.columns) == [
        "subject",
        "n_takes",
        "n_visemes",
        "n_expressions",
        "left_out",
        "stopped",
        "motion_rms_all_mm_car",
        "motion_rms_all_mm_too",  # paper order of the visemes
        "noise_relative_unmasked_car",
        "noise_relative_unmasked_too",
        "ccr_1",
        "ccr_2",
        "ccr_3",
        "modal_f1_hz",
        "mesh_rms_mm_max",
    ]
    assert list(table["subject"]) == ["bob", "alice"]
    assert np.isnan(table.loc[0, "motion_rms_all_mm_too"]) and np.isnan(
        table.loc[0, "mesh_rms_mm_max"]
    )
    assert table.loc[1, "mesh_rms_mm_max"] == 0.5


def test_write_cohort_summary_round_trips_and_plots(stores, tmp_path):
    alice, bob, _ = stores
    out_tsv, out_png = tmp_path / "cohort" / "summary.tsv", tmp_path / "cohort" / "summary.png"
    table = write_cohort_summary(
        {"alice": alice, "bob": bob},
        {"alice": {"summary": {"mesh_rms_mm_max": 0.5}}},
        out_tsv,
        out_png,
    )
    back = pd.read_csv(out_tsv, sep="\t", comment="#")
    pd.testing.assert_frame_equal(back, table, check_dtype=False, rtol=1e-5)
    assert back["mesh_rms_mm_max"].isna().tolist() == [False, True]
    # the column dictionary on top: every column (families by pattern), unit and definition
    dictionary = read_dictionary(out_tsv).set_index("column")
    assert dictionary.index.tolist() == [
        "subject",
        "n_takes",
        "n_visemes",
        "n_expressions",
        "left_out",
        "stopped",
        "motion_rms_all_mm_{label}",
        "noise_relative_unmasked_{label}",
        "ccr_{k}",
        "modal_f1_hz",
        "mesh_rms_mm_max",
    ]
    assert dictionary.loc["motion_rms_all_mm_{label}", "unit"] == "mm"
    assert "over all template vertices" in dictionary.loc["motion_rms_all_mm_{label}", "definition"]
    assert dictionary.loc["mesh_rms_mm_max", "unit"] == "mm"
    img = cv2.imread(str(out_png))
    assert img is not None and img.shape[0] > 100 and img.shape[1] > 300


def test_a_stopped_subject_is_a_row_that_says_why(stores, tmp_path):
    """The subjects that finished as before, then a row per stopped subject with its reason
    and nothing else (a run whose subject stopped writes the others' summary)."""
    alice, bob, _ = stores
    out_tsv, out_png = tmp_path / "summary.tsv", tmp_path / "summary.png"
    finished = write_cohort_summary({"alice": alice}, {}, out_tsv, out_png)
    table = write_cohort_summary(
        {"alice": alice}, {}, out_tsv, out_png, {"bob": "neutral.pts: n_points: 67"}
    )
    assert table["subject"].tolist() == ["alice", "bob"]
    pd.testing.assert_frame_equal(table.iloc[:1], finished, check_dtype=False)
    assert table["stopped"].isna().tolist() == [True, False]
    assert table["stopped"].iloc[1] == "neutral.pts: n_points: 67"
    assert table.iloc[1].drop(["subject", "stopped"]).isna().all()
    back = pd.read_csv(out_tsv, sep="\t", comment="#")
    pd.testing.assert_frame_equal(back, table, check_dtype=False, rtol=1e-5)


def test_the_cohort_plot_has_one_panel_per_unit(stores, tmp_path, monkeypatch):
    """Material error (%) first, motion (mm), CCR (%, its axis from 0), then the accuracy split
    by unit: mm, degrees, fraction, px, and a unit's minima of what should be high (a coverage)
    apart from its errors (the figures audit: a stereo coverage sat among the errors)."""
    alice, bob, _ = stores
    summary = {
        "mesh_rms_mm_max": 0.5,
        "align_rotation_deg_max": 0.25,
        "motion_relative_error_max": 0.1,
        "stereo_coverage_min": 0.9,
        "click_noise_px_used": 0.5,
    }
    table = cohort_table(
        [subject_summary(alice, {"summary": summary, "takes": ALICE_TAKES}), subject_summary(bob)]
    )
    drawn = {}
    real = cohort_module.Figure.savefig

    def savefig(fig, path, **kwargs):
        drawn["labels"] = [ax.get_ylabel() for ax in fig.axes if ax.get_visible()]
        drawn["ticks"] = [
            [t.get_text() for t in ax.get_xticklabels()] for ax in fig.axes if ax.get_visible()
        ]
        drawn["titles"] = [ax.get_title() for ax in fig.axes if ax.get_visible()]
        drawn["ccr"] = next(ax.get_ylim() for ax in fig.axes if ax.get_ylabel() == "CCR (%)")
        return real(fig, path, **kwargs)

    monkeypatch.setattr(cohort_module.Figure, "savefig", savefig)
    plot_cohort(table, {}, tmp_path / "c.png")
    assert drawn["labels"] == [
        "error against the material motion (%)",
        "motion RMS over all vertices (mm)",
        "CCR (%)",
        "mm",
        "degrees",
        "fraction",
        "fraction",
        "px",
    ]
    assert drawn["ticks"][0] == ["car", "too", "smile (expr.)"]
    assert drawn["ticks"][1] == ["car", "too"]
    assert drawn["ticks"][3:] == [
        ["mesh_rms_mm_max"],
        ["align_rotation_deg_max"],
        ["motion_relative_error_max"],
        ["stereo_coverage_min"],
        ["click_noise_px_used"],
    ]
    assert (
        drawn["titles"][6] == "Accuracy against ground truth (the least of each, higher is better)"
    )
    assert drawn["ccr"] == (0.0, 100.0)
    assert (tmp_path / "c.png").stat().st_size > 0


def test_bad_inputs_are_named(stores, tmp_path):
    alice, _, _ = stores
    with h5py.File(alice, "a") as h5:
        del h5[paths.pca("ccr")]  # a subject without visemes: no PCA, NaN in the CCR columns
    row = subject_summary(alice).row
    assert all(np.isnan(row[f"ccr_{i}"]) for i in (1, 2, 3))
    with h5py.File(alice, "a") as h5:
        del h5[paths.modal("frequencies_hz")]
    with pytest.raises(
        InputError,
        match=rf"alice.h5: {re.escape(paths.modal('frequencies_hz'))}: missing \(the subject did not finish\)",
    ):
        subject_summary(alice)
    with pytest.raises(InputError, match="store not found"):
        subject_summary(tmp_path / "nobody.h5")
    with pytest.raises(InputError, match="no subject to summarise"):
        write_cohort_summary({}, {}, tmp_path / "a.tsv", tmp_path / "a.png")
    with pytest.raises(InputError, match=r"no subject to summarise \(stopped: bob: bad neutral\)"):
        write_cohort_summary({}, {}, tmp_path / "a.tsv", tmp_path / "a.png", {"bob": "bad neutral"})
    assert np.isnan(motion_rms(np.full((4, 3), np.nan)))


@pytest.mark.slow
def test_cohort_rule_summarises_the_tiny_run(tmp_path_factory):
    run = tiny_run(tmp_path_factory, ["results/cohort/summary.tsv"])
    table = pd.read_csv(run.path("results", "cohort", "summary.tsv"), sep="\t", comment="#")
    assert run.path("results", "cohort", "summary.png").stat().st_size > 0
    assert list(table["subject"]) == [SUBJECT]
    row = table.iloc[0]
    assert (row["n_takes"], row["n_visemes"], row["n_expressions"]) == (4, 2, 1)
    with h5py.File(run.path("results", SUBJECT, f"{SUBJECT}.h5")) as h5:
        for take in ("car", "too"):
            m = h5[paths.viseme(take, "motion")][()]
            want = np.sqrt(np.sum(m**2) / len(m))
            assert row[f"motion_rms_all_mm_{take}"] == pytest.approx(want, rel=1e-5)
        ccr, f1 = h5[paths.pca("ccr")][()], h5[paths.modal("frequencies_hz")][0]
    want = np.full(3, np.nan)
    want[: min(3, len(ccr))] = ccr[:3]  # neutral + two visemes: two components, ccr_3 is NA
    np.testing.assert_allclose([row["ccr_1"], row["ccr_2"], row["ccr_3"]], want, rtol=1e-5)
    assert row["modal_f1_hz"] == pytest.approx(f1, rel=1e-5)
    accuracy = json.loads(run.path("results", SUBJECT, "accuracy.json").read_text())
    for key, value in accuracy["summary"].items():
        if isinstance(value, (int, float)):  # a nested entry (by_modality) is no column
            assert row[key] == pytest.approx(value, rel=1e-5)
    # the headline columns: each viseme's and expression's error against the material motion,
    # as accuracy.json gives it (one take per label in the tiny run)
    with h5py.File(run.path("results", SUBJECT, f"{SUBJECT}.h5")) as h5:
        kinds = {t: h5[paths.take(t)].attrs["kind"] for t in h5[paths.TAKES]}
        labels = {t: h5[paths.take(t)].attrs["label"] for t in h5[paths.TAKES]}
    seen = 0
    for take, entry in accuracy["takes"].items():
        kind = kinds[take].decode() if isinstance(kinds[take], bytes) else str(kinds[take])
        label = labels[take].decode() if isinstance(labels[take], bytes) else str(labels[take])
        key = {"viseme": "motion", "expression": "expression"}.get(kind)
        if key not in entry:
            continue
        for name in (
            "material_relative_error",
            "material_rms_error_mm",
            "material_normal_rms_error_mm",
            "material_tangential_rms_error_mm",
        ):
            assert row[f"{name}_{kind}_{label}"] == pytest.approx(entry[key][name], rel=1e-5)
            seen += 1
    assert seen >= 8  # two visemes and the expression
