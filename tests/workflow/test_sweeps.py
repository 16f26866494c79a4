"""Parameter sweeps (scan2morph.report.sweep, workflow/rules/sweeps.smk).

The sweep table is checked against the config schema (unit tests, and a bad table stops a real
run before any job); a sweep combination equal to the config reproduces the pipeline's own
accuracy (the oracle), a changed one changes only what it should.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import yaml

from scan2morph.errors import InputError
from scan2morph.evaluate.truth import read_truth
from scan2morph.report import sweep as sweep_module
from scan2morph.report.sweep import (
    config_values,
    one_at_a_time,
    plot_sweep,
    sweep_summary,
    write_sweep_summary,
)
from scan2morph.stages import Run, Subject
from scan2morph.store import paths, read_part
from scan2morph.sweep import (
    check_sweep_rows,
    first_stage,
    read_sweep_table,
    rerun_accuracy,
    sweep_settings,
)
from scan2morph.tables import read_dictionary
from scan2morph.template import load_template
from tests.support.configs import repo_config
from tests.support.tiny_run import SUBJECT, TAKES, tiny_config, tiny_run
from tests.support.workflow_api import REPO

SCHEMA = REPO / "schemas" / "config.schema.yaml"
CONFIG = repo_config()


def _table(tmp_path, text):
    path = tmp_path / "sweeps.tsv"
    path.write_text(text)
    return path


def _flat(d, prefix=""):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _flat(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v


def _assert_same_accuracy(got: dict, want: dict):
    got = dict(_flat({k: v for k, v in got.items() if k != "sweep"}))
    want = dict(_flat(want))
    assert got.keys() == want.keys()
    for key, value in want.items():
        if isinstance(value, float):
            assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12, nan_ok=True), key
        else:
            assert got[key] == value, key


# --- the table ---
def test_a_good_table_is_read_with_typed_values(tmp_path):
    path = _table(
        tmp_path,
        "# a comment\n"
        "smoothing.iterations\tmask.radius_mm\ttemplate.fiducials.viseme\n"
        "30\t20.0\topen\n"
        "\n"
        "0\t15\tclosed\n",
    )
    table = read_sweep_table(path, SCHEMA)
    assert table.columns == ("smoothing.iterations", "mask.radius_mm", "template.fiducials.viseme")
    assert table.rows == (
        {"smoothing.iterations": 30, "mask.radius_mm": 20.0, "template.fiducials.viseme": "open"},
        {"smoothing.iterations": 0, "mask.radius_mm": 15, "template.fiducials.viseme": "closed"},
    )
    assert type(table.rows[0]["smoothing.iterations"]) is int
    assert type(table.rows[0]["mask.radius_mm"]) is float
    assert list(table.frame().columns) == [
        "smoothing_iterations",
        "mask_radius_mm",
        "template_fiducials_viseme",
    ]
    assert table.first_stage == "landmarks"  # template.*: the fold test of detected points
    assert first_stage(["smoothing.w", "align.icp.kernel_k_mm"]) == "align"
    assert first_stage(["refine.jaw.end", "mask.radius_mm"]) == "refine"
    assert first_stage(["motion_noise.click_noise_px"]) == "motion_noise"
    assert first_stage(["repair.max_hole_px", "mask.radius_mm"]) == "repair"
    assert read_sweep_table(_table(tmp_path, "# nothing\n"), SCHEMA).rows == ()


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "smoothing.iteration\n30\n",
            r"column 'smoothing.iteration': names no config key \(no 'iteration' under smoothing; keys there: confidence_relief, expression_iterations, iterations, max_stretch, w\)",
        ),
        (
            "smooth.w\n0.1\n",
            r"column 'smooth.w': names no config key \(no 'smooth' under the top level",
        ),
        (
            "smoothing.iterations\n3.5\n",
            r"line 2, column 'smoothing.iterations': 3.5 is not of type 'integer'",
        ),
        ("smoothing.iterations\nmany\n", r"'many' is not of type 'integer'"),
        ("smoothing.w\n1.5\n", r"1.5 is greater than the maximum of 1"),
        ("smoothing.max_stretch\n1\n", r"1 is less than or equal to the minimum of 1"),
        ("smoothing.confidence_relief\n1.5\n", r"1.5 is greater than the maximum of 1"),
        ("smoothing.expression_iterations\n-1\n", r"-1 is less than the minimum of 0"),
        (
            "align.icp.robust_kernel\ncauchy\n",
            r"'cauchy' is not one of \['tukey', 'huber', 'none'\]",
        ),
        ("refine.jaw.end\n1.5\n", r"1.5 is greater than the maximum of 1"),
        ("refine.jaw_end\n0.4\n", r"column 'refine.jaw_end': renamed to refine.jaw.end"),
        (
            "align.kernel_k_mm\n0.5\n",
            r"column 'align.kernel_k_mm': renamed to align.icp.kernel_k_mm",
        ),
        ("mask.radius_mm\n-2\n", r"-2 is less than or equal to the minimum of 0"),
        (
            "modal.modes\n20\n",
            r"column 'modal.modes': a sweep re-runs the stages from repair to accuracy",
        ),
        ("mask.paths\nx\n", r"column 'mask.paths': a swept key must hold a scalar"),
        ("smoothing.iterations\tsmoothing.w\n30\n", r"line 2: 1 fields, expected 2"),
        ("smoothing.iterations\n30\n30\n", r"line 3: repeats the combination of line 2"),
        ("smoothing.iterations\tsmoothing.w\n30\t\n", r"line 2, column 'smoothing.w': empty value"),
        ("smoothing.w\tsmoothing.w\n0.1\t0.2\n", r"header: repeated column"),
        ("smoothing.w\nnan\n", r"'nan' is not a finite number"),
        ("smoothing.iterations\n.inf\n", r"'.inf' is not a finite number"),
        ("mask.radius_mm\ninf\n", r"'inf' is not a finite number"),
        ("smoothing.max_stretch\n-.inf\n", r"-inf is less than or equal to the minimum of 1"),
        ("motion_noise.draws\n1\n", r"1 is less than the minimum of 2"),
        ("motion_noise.click_noise_px\n0\n", r"0 is not valid under any of the given schemas"),
        ("motion_noise.click_noise_px\nmeasured\n", r"'measured' is not valid under any"),
    ],
)
def test_a_bad_table_is_refused_naming_line_column_and_rule(tmp_path, text, message):
    with pytest.raises(InputError, match=message):
        read_sweep_table(_table(tmp_path, text), SCHEMA)


def test_a_table_takes_values_as_the_config_takes_them(tmp_path):
    """An integral float at an integer key is the integer (10.0 and 1e1 are 10, the same row as
    10), and ``.inf`` is taken where the key's schema says what it means (``x-infinite``:
    ``smoothing.max_stretch``, no limit), as the config takes them."""
    table = read_sweep_table(_table(tmp_path, "smoothing.iterations\n10.0\n30\n"), SCHEMA)
    assert table.rows == ({"smoothing.iterations": 10}, {"smoothing.iterations": 30})
    assert type(table.rows[0]["smoothing.iterations"]) is int
    with pytest.raises(InputError, match=r"line 3: repeats the combination of line 2"):
        read_sweep_table(_table(tmp_path, "smoothing.iterations\n10\n1e1\n"), SCHEMA)
    table = read_sweep_table(_table(tmp_path, "smoothing.max_stretch\n.inf\n1.5\n"), SCHEMA)
    assert [r["smoothing.max_stretch"] for r in table.rows] == [np.inf, 1.5]


def test_a_string_value_must_fit_in_a_folder_name(tmp_path):
    schema = {"properties": {"align": {"properties": {"name": {"type": "string"}}}}}
    assert read_sweep_table(_table(tmp_path, "align.name\nab_1.5-x\n"), schema).rows[0] == {
        "align.name": "ab_1.5-x"
    }
    with pytest.raises(InputError, match=r"'a/b': expected letters, digits and \. _ \+ - only"):
        read_sweep_table(_table(tmp_path, "align.name\na/b\n"), schema)


def test_missing_table_is_named(tmp_path):
    with pytest.raises(InputError, match="sweeps.tsv: sweep table not found"):
        read_sweep_table(tmp_path / "sweeps.tsv", SCHEMA)


def test_sweep_settings_override_a_copy():
    row = {"smoothing.iterations": np.int64(5), "template.fiducials.viseme": "closed"}
    settings = sweep_settings(CONFIG, row)
    assert settings["smoothing"] == CONFIG["smoothing"] | {"iterations": 5}
    assert type(settings["smoothing"]["iterations"]) is int  # numpy scalars become Python's
    assert settings["template"]["fiducials"]["viseme"] == "closed"
    assert CONFIG["template"]["fiducials"]["viseme"] == "open"  # the config is untouched
    assert set(settings) == {
        "repair",
        "landmarks",
        "template",
        "align",
        "refine",
        "mask",
        "smoothing",
        "motion_noise",
        "quality",
    }


def test_a_combination_that_contradicts_the_config_is_named(tmp_path):
    """Each value may be valid alone and a combination still contradict the config (the jaw
    prior's start above its end): the table's check names the combination and the rule, as the
    config's own check names the rule; the combinations that agree pass."""
    good = read_sweep_table(_table(tmp_path, "refine.jaw.start\n0.0\n0.2\n"), SCHEMA)
    check_sweep_rows(good, CONFIG)
    bad = read_sweep_table(_table(tmp_path, "refine.jaw.start\n0.0\n0.5\n"), SCHEMA)
    with pytest.raises(
        InputError,
        match=r"sweeps\.tsv: combination 2 \(refine\.jaw\.start = 0\.5\): config: refine\.jaw: "
        r"start, end: expected 0 <= start < end <= 1, got 0\.5 and 0\.3$",
    ):
        check_sweep_rows(bad, CONFIG)


# --- load-time validation through Snakemake ---
def _snakemake(work: Path, configfile: Path, *args) -> subprocess.CompletedProcess:
    cmd = [
        str(Path(sys.executable).with_name("snakemake")),
        *args,
        "--cores",
        "1",
        "-s",
        str(REPO / "Snakefile"),
        "-d",
        str(work),
        "--configfile",
        str(REPO / "config" / "config.yaml"),
        str(configfile),
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
@pytest.mark.parametrize(
    "text, message",
    [
        ("smoothing.iteration\n30\n", "column 'smoothing.iteration': names no config key"),
        ("mask.radius_mm\ntwenty\n", "column 'mask.radius_mm': 'twenty' is not of type 'number'"),
        ("refine.jaw.start\n0.5\n", "combination 1 (refine.jaw.start = 0.5): config: refine.jaw"),
    ],
)
def test_a_bad_table_stops_the_run_before_any_job(tmp_path, text, message):
    configfile = tiny_config(tmp_path)
    (tmp_path / "sweeps.tsv").write_text(text)
    res = _snakemake(tmp_path, configfile)
    assert res.returncode != 0
    assert message in res.stderr + res.stdout
    assert not (tmp_path / "results").exists() and not (tmp_path / "logs").exists()
    # one line, as a bad config's: no stack frames around it
    (line,) = [x for x in res.stderr.splitlines() if message in x]
    assert line.startswith("Error: ") and "Traceback" not in res.stderr
    assert 'File "' not in res.stderr, res.stderr


# --- a tiny sweep end to end ---
@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return tiny_run(tmp_path_factory, [f"results/{SUBJECT}/accuracy.json"])


@pytest.fixture(scope="module")
def sweep(run, tmp_path_factory):
    run.sweeps.write_text("smoothing.iterations\tmask.radius_mm\n30\t20.0\n0\t20.0\n30\t10\n")
    return tiny_run(tmp_path_factory, ["sweep_all"])


def _result(run, iterations, radius):
    folder = run.path(
        "results", "sweeps", f"smoothing_iterations~{iterations}", f"mask_radius_mm~{radius}"
    )
    return json.loads((folder / SUBJECT / "accuracy.json").read_text())


@pytest.mark.slow
def test_the_config_combination_reproduces_the_pipeline_accuracy(sweep):
    pipeline = json.loads(sweep.path("results", SUBJECT, "accuracy.json").read_text())
    result = _result(sweep, 30, "20.0")
    assert result["sweep"] == {"smoothing.iterations": 30, "mask.radius_mm": 20.0}
    _assert_same_accuracy(result, pipeline)


@pytest.mark.slow
def test_changed_values_change_only_the_stages_they_feed(sweep):
    base, raw = _result(sweep, 30, "20.0"), _result(sweep, 0, "20.0")
    small_mask = _result(sweep, 30, "10")
    for take in base["takes"]:
        assert raw["takes"][take]["mesh"] == base["takes"][take]["mesh"]  # fit is upstream
    car, car_raw = base["takes"]["car"]["motion"], raw["takes"]["car"]["motion"]
    assert car_raw["rms_error_mm"] != car["rms_error_mm"]
    # without smoothing the processed motion is the raw motion outside the mask
    assert car_raw["relative_error"] != car["relative_error"]
    assert (
        small_mask["takes"]["car"]["motion"]["masked_true_motion_share"]
        <= car["masked_true_motion_share"]
    )


@pytest.mark.slow
def test_summary_collects_every_combination(sweep):
    table = pd.read_csv(sweep.path("results", "sweeps", "summary.tsv"), sep="\t", comment="#")
    assert list(table.columns[:3]) == ["smoothing.iterations", "mask.radius_mm", "subject"]
    assert table[["smoothing.iterations", "mask.radius_mm"]].values.tolist() == [
        [30, 20.0],
        [0, 20.0],
        [30, 10.0],
    ]
    for _, row in table.iterrows():
        radius = "20.0" if row["mask.radius_mm"] == 20 else "10"
        summary = _result(sweep, int(row["smoothing.iterations"]), radius)["summary"]
        for key, value in summary.items():
            if isinstance(value, dict):  # summary.by_modality: nested, not a column
                continue
            assert row[key] == pytest.approx(value, rel=1e-5)
    img = cv2.imread(str(sweep.path("results", "sweeps", "summary.png")))
    assert img is not None and img.shape[0] > 200
    # the dictionary names the config's value of each swept key
    dictionary = read_dictionary(sweep.path("results", "sweeps", "summary.tsv"))
    definition = dict(zip(dictionary["column"], dictionary["definition"], strict=True))
    assert definition["smoothing.iterations"].endswith("the config's value: 30")
    assert set(dictionary["column"]) == set(table.columns)


# --- the summary table and plot (made-up accuracy) ---
_ROWS = [
    {"smoothing.iterations": 30, "mask.radius_mm": 20.0},  # the config's values
    {"smoothing.iterations": 0, "mask.radius_mm": 20.0},
    {"smoothing.iterations": 100, "mask.radius_mm": 20.0},
    {"smoothing.iterations": 30, "mask.radius_mm": 10},
    {"smoothing.iterations": 0, "mask.radius_mm": 10},  # two keys off the config
]
_PARAMS = ["smoothing.iterations", "mask.radius_mm"]
_DEFAULTS = {"smoothing.iterations": 30, "mask.radius_mm": 20.0}


def _results():
    out = []
    for i, row in enumerate(_ROWS):
        for k, subject in enumerate(("synth01", "synth02")):
            summary = {
                "mesh_rms_mm_max": 0.1 + k,
                "align_translation_mm_max": 0.2,
                "align_rotation_deg_max": 0.05 * i,
                "motion_relative_error_max": 0.1 + 0.01 * i,
                "masked_true_motion_share_max": 0.001,
                "click_noise_px_used": 0.5,
                "stereo_coverage_min": None,
            }
            out.append((row, subject, {"summary": summary}))
    return out


def test_config_values_reads_dotted_paths():
    config = {"smoothing": {"iterations": 30, "w": 0.1}, "mask": {"radius_mm": 20.0}}
    assert config_values(config, _PARAMS) == _DEFAULTS
    with pytest.raises(InputError, match="mask.nope: not in the config"):
        config_values(config, ["mask.nope"])


def test_rows_are_sorted_into_one_key_at_a_time_slices():
    table = sweep_summary(_results())
    default, varied = one_at_a_time(table, _PARAMS, _DEFAULTS)
    assert default.tolist() == [True, True] + [False] * 8  # 20 and 20.0 are one value
    assert varied["smoothing.iterations"].tolist() == [False] * 2 + [True] * 4 + [False] * 4
    assert varied["mask.radius_mm"].tolist() == [False] * 6 + [True] * 2 + [False] * 2


def _drawn_axes(monkeypatch) -> dict:
    """``{"axes": ...}``, filled with the axes of the next figure :mod:`~scan2morph.report.sweep`
    saves."""
    drawn = {}
    real = sweep_module.Figure.savefig

    def savefig(fig, path, **kwargs):
        drawn["axes"] = fig.axes
        return real(fig, path, **kwargs)

    monkeypatch.setattr(sweep_module.Figure, "savefig", savefig)
    return drawn


def test_the_sweep_plot_has_one_panel_row_per_unit_and_the_varied_key_on_x(tmp_path, monkeypatch):
    table = sweep_summary(_results())
    drawn = _drawn_axes(monkeypatch)
    plot_sweep(table, _PARAMS, tmp_path / "s.png", _DEFAULTS)
    axes = np.array(drawn["axes"]).reshape(-1, len(_PARAMS))
    # mm, degrees, fraction, px; the all-NA metric is left out
    assert [row[0].get_ylabel() for row in axes] == ["mm", "degrees", "fraction", "px"]
    assert axes[-1, 0].get_xlabel().startswith("smoothing.iterations")
    assert axes[-1, 1].get_xlabel().startswith("mask.radius_mm")
    degrees = axes[1]
    # the config's value: a dashed vertical line; per subject, one line through the slice
    for ax, x_default, xs in ((degrees[0], 30, [0, 30, 100]), (degrees[1], 20, [10, 20])):
        lines = [ln for ln in ax.get_lines() if ln.get_linestyle() != ":"]
        vertical = [ln for ln in lines if np.ptp(ln.get_xdata()) == 0 and len(ln.get_xdata()) == 2]
        assert [float(ln.get_xdata()[0]) for ln in vertical] == [x_default]
        data = [ln for ln in lines if ln not in vertical]
        assert len(data) == 2  # two subjects, one metric
        for ln in data:
            assert np.asarray(ln.get_xdata(), float).tolist() == xs
            assert ln.get_linestyle() != "--"  # the subjects' lines are not the config's
    # the row off the config in two keys (rotation 0.2) is drawn nowhere
    ys = np.concatenate([ln.get_ydata() for ax in degrees for ln in ax.get_lines()])
    assert not np.isclose(ys.astype(float), 0.2).any()
    assert (tmp_path / "s.png").stat().st_size > 0


def test_an_integer_key_drawn_at_one_value_has_one_integer_tick(tmp_path, monkeypatch):
    """Only the config's value of an integer key drawn: its ticks are integers, that one among
    them (it used to get fractional ticks, 0.945 ... 1.05)."""
    drawn = _drawn_axes(monkeypatch)
    results = [
        ({**row, "smoothing.iterations": 1}, subject, accuracy)
        for row, subject, accuracy in _results()
        if row["smoothing.iterations"] == 30
    ]
    defaults = {**_DEFAULTS, "smoothing.iterations": 1}
    plot_sweep(sweep_summary(results), _PARAMS, tmp_path / "s.png", defaults)
    ax = np.array(drawn["axes"]).reshape(-1, len(_PARAMS))[-1, 0]
    lo, hi = ax.get_xlim()
    ticks = [t for t in ax.get_xticks() if lo <= t <= hi]
    assert 1.0 in ticks and all(float(t).is_integer() for t in ticks), ticks


def test_the_sweep_summary_table_carries_its_dictionary(tmp_path):
    table = write_sweep_summary(
        _results(), _PARAMS, tmp_path / "summary.tsv", tmp_path / "summary.png", _DEFAULTS
    )
    back = pd.read_csv(tmp_path / "summary.tsv", sep="\t", comment="#")
    pd.testing.assert_frame_equal(back, table, check_dtype=False)
    # each swept value as its folder spells it (str: mask_radius_mm~20.0), not as the table's
    # float format (20)
    text = pd.read_csv(tmp_path / "summary.tsv", sep="\t", comment="#", dtype=str)
    assert text["mask.radius_mm"].tolist() == [str(r["mask.radius_mm"]) for r, _, _ in _results()]
    assert text["mask.radius_mm"].iloc[0] == "20.0"
    dictionary = read_dictionary(tmp_path / "summary.tsv").set_index("column")
    assert dictionary.index.tolist() == list(table.columns)
    assert dictionary.loc["mask.radius_mm", "unit"] == "mm"
    assert dictionary.loc["align_rotation_deg_max", "unit"] == "deg"
    assert dictionary.loc["stereo_coverage_min", "unit"] == "fraction"


def test_a_combination_whose_stages_refuse_the_subject_is_a_row_that_says_why(
    tmp_path, monkeypatch
):
    """A stage refusing the subject with a combination's values (a stricter fit leaving the
    neutral out) stopped the whole sweep, and the previous table's summary stayed in place: the
    combination is now a row with no metrics and the reason, and the others are summarised."""
    from scan2morph import sweep as sweep_lib

    def refuse(*args, **kwargs):
        raise InputError("synth01/neutral", "only 89.7% of the template's vertices fall on range")

    monkeypatch.setattr(sweep_lib, "rerun_accuracy", refuse)
    refused = sweep_lib.combination_accuracy({}, None, {}, "repair")
    assert refused == {
        "summary": {},
        "refused": "synth01/neutral: only 89.7% of the template's vertices fall on range",
    }
    results = _results()
    results[2] = (results[2][0], results[2][1], refused)
    table = write_sweep_summary(
        results, _PARAMS, tmp_path / "summary.tsv", tmp_path / "summary.png", _DEFAULTS
    )
    assert table.columns[-1] == "refused"
    assert table["refused"].iloc[2].startswith("synth01/neutral: only 89.7%")
    assert table["refused"].drop(index=2).isna().all()
    assert table.drop(columns=[*_PARAMS, "subject", "refused"]).iloc[2].isna().all()
    back = pd.read_csv(tmp_path / "summary.tsv", sep="\t", comment="#")
    pd.testing.assert_frame_equal(back, table, check_dtype=False)
    assert (tmp_path / "summary.png").stat().st_size > 0


@pytest.mark.slow
def test_another_sweep_table_reruns_no_subject(sweep, tmp_path):
    """Another table (``sweeps:`` in an extra config file, as docs/configuration.md says) runs
    its combinations only: the table's path changed the config's hash, and every subject's
    store, figures and report were built again, and the earlier tables' results went out of
    date with them."""
    table = tmp_path / "mine.tsv"
    table.write_text("smoothing.iterations\n30\n5\n")
    mine = tmp_path / "mine.yaml"
    mine.write_text(
        yaml.safe_dump(yaml.safe_load(sweep.configfile.read_text()) | {"sweeps": str(table)})
    )
    res = _snakemake(sweep.work, mine, "sweep_all", "-n", "--quiet", "rules")
    assert res.returncode == 0, res.stderr
    rules = {line.split()[0] for line in res.stdout.splitlines() if line.strip()}
    assert "sweep" in rules and not {r for r in rules if r.startswith("subject")}, rules


@pytest.mark.slow
def test_a_moved_sheet_reruns_no_subject(sweep, tmp_path):
    """The same sheet in another folder (``subjects:`` naming it): nothing to compute, so no
    subject job runs. The sheet's path was in the config's hash, and moving the sheet re-ran
    every subject job and rebuilt every store, report and figure after it."""
    moved = tmp_path / "elsewhere" / "subjects.tsv"
    moved.parent.mkdir()
    shutil.copy(sweep.path("subjects.tsv"), moved)
    mine = tmp_path / "moved.yaml"
    mine.write_text(
        yaml.safe_dump(yaml.safe_load(sweep.configfile.read_text()) | {"subjects": str(moved)})
    )
    res = _snakemake(sweep.work, mine, "-n", "--quiet", "rules")
    assert res.returncode == 0, res.stderr
    rules = {line.split()[0] for line in res.stdout.splitlines() if line.strip()}
    assert not {r for r in rules if r.startswith(("subject", "check", "take"))}, res.stdout


@pytest.mark.slow
def test_sweeps_are_not_part_of_the_default_target(sweep):
    res = _snakemake(sweep.work, sweep.configfile, "-n", "--quiet", "rules")
    assert res.returncode == 0, res.stderr
    rules = {line.split()[0] for line in res.stdout.splitlines() if line.strip()}
    assert not {"sweep", "sweep_summary", "sweep_all"} & rules


@pytest.mark.slow
def test_rerun_from_repair_reproduces_the_pipeline(run):
    """Every stage re-run in memory from the raw range images, with the config's values."""
    takes = [t["take"] for t in TAKES]
    raw = {}
    for take in takes:
        raw |= read_part(run.path("results", SUBJECT, "takes", take, "ingest.h5"))
    truths = {
        t: read_truth(run.path("results", "synthetic", SUBJECT, "truth", f"{t}.npz")) for t in takes
    }
    settings = sweep_settings(CONFIG, {})  # the tiny config keeps these sections as they are
    subject = Subject(SUBJECT, *_kinds_labels())
    result = rerun_accuracy(
        read_part(run.path("results", SUBJECT, f"{SUBJECT}.h5")),
        Run(subject, load_template(run.path("resources", "template.npz")), settings),
        truths,
        "repair",
        raw=raw,
    )
    _assert_same_accuracy(
        result, json.loads(run.path("results", SUBJECT, "accuracy.json").read_text())
    )


@pytest.mark.slow
def test_rerun_refuses_bad_input(run):
    store = {paths.landmarks("neutral"): np.zeros((68, 2))}
    tpl = load_template(run.path("resources", "template.npz"))
    settings = sweep_settings(CONFIG, {})
    good = Run(Subject(SUBJECT, *_kinds_labels()), tpl, settings)
    with pytest.raises(
        InputError,
        match=r"start stage: expected one of \('repair', 'landmarks', 'fit', 'align', 'refine', "
        r"'consensus', 'motion', 'motion_noise'\)",
    ):
        rerun_accuracy(store, good, {}, "morph")
    with pytest.raises(InputError, match="/takes/neutral/raw/xyz: missing"):
        rerun_accuracy(store, good, {}, "repair")
    no_neutral = Run(Subject(SUBJECT, {"car": "viseme"}, {"car": "car"}), tpl, settings)
    with pytest.raises(InputError, match=r"takes: expected exactly one neutral take, got \[\]"):
        rerun_accuracy(store, no_neutral, {}, "motion")


def _kinds_labels():
    return {t["take"]: t["kind"] for t in TAKES}, {t["take"]: t["label"] for t in TAKES}
