"""Tables and their column dictionaries (scan2morph.tables): one writer, one meaning per name."""

from __future__ import annotations

import os
import stat

import numpy as np
import pandas as pd
import pytest

from scan2morph import tables
from scan2morph.errors import InputError
from scan2morph.morph.pca import pca, pca_tables
from scan2morph.stages import motion_noise
from scan2morph.tables import Column, describe, read_dictionary, read_table, write_table

#: Every dictionary, by the table it describes.
DICTIONARIES = {
    "motion_noise": tables.MOTION_NOISE,
    "pca_eigenvalues": tables.PCA_EIGENVALUES,
    "pca_coefficients": tables.PCA_COEFFICIENTS,
    "modal_coordinates": tables.MODAL_COORDINATES,
    "modal_reconstruction": tables.MODAL_RECONSTRUCTION,
    "cohort": (*tables.COHORT, *tables.ACCURACY),
    "sweeps": tables.sweep_dictionary(
        ["mask.radius_mm", "smoothing.iterations"],
        [c.name for c in tables.ACCURACY],
        {"mask.radius_mm": 20.0},
    ),
}


def test_a_table_carries_its_dictionary_and_reads_back_with_comment(tmp_path):
    path = tmp_path / "t.tsv"
    table = pd.DataFrame({"take": ["neutral", "car"], "w1": [1.5, -2.25], "w2": [np.nan, 3.0]})
    written = write_table(path, table, tables.PCA_COEFFICIENTS)
    assert [c.name for c in written] == ["take", "w{k}"]
    lines = path.read_text().splitlines()
    assert lines[0] == "# column\tunit\tdefinition"
    assert lines[1].startswith("# take\t-\t") and lines[2].startswith("# w{k}\tmm\t")
    assert lines[3] == "take\tw1\tw2"
    pd.testing.assert_frame_equal(pd.read_csv(path, sep="\t", comment="#"), table)
    pd.testing.assert_frame_equal(read_table(path), table)
    dictionary = read_dictionary(path)
    assert list(dictionary.columns) == ["column", "unit", "definition"]
    assert dictionary["column"].tolist() == ["take", "w{k}"]
    assert dictionary["unit"].tolist() == ["-", "mm"]


def test_an_empty_table_keeps_its_header_and_dictionary(tmp_path):
    path = tmp_path / "e.tsv"
    write_table(
        path, pd.DataFrame(columns=["component", "eigenvalue", "cr", "ccr"]), tables.PCA_EIGENVALUES
    )
    assert read_table(path).columns.tolist() == ["component", "eigenvalue", "cr", "ccr"]
    assert read_dictionary(path)["column"].tolist() == ["component", "eigenvalue", "cr", "ccr"]


def test_an_undocumented_column_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"column 'motion_rms_mm': no entry"):
        write_table(tmp_path / "x.tsv", pd.DataFrame({"motion_rms_mm": [1.0]}), tables.MOTION_NOISE)
    assert not (tmp_path / "x.tsv").exists()
    twice = (Column("a_{x}", "mm", "one"), Column("{y}_b", "mm", "two"))
    with pytest.raises(ValueError, match="two entries"):
        describe(["a_b"], twice)
    with pytest.raises(InputError, match="no column dictionary"):
        (tmp_path / "plain.tsv").write_text("a\tb\n1\t2\n")
        read_dictionary(tmp_path / "plain.tsv")


def test_patterns_match_their_families_only():
    w = Column("w{k}", "mm", "x")
    assert w.matches("w1") and w.matches("w12")
    assert not w.matches("w0") and not w.matches("wx") and not w.matches("w")
    assert Column("K={k}", "mm", "x").matches("K=100")
    label = Column("motion_rms_all_mm_{label}", "mm", "x")
    assert label.matches("motion_rms_all_mm_car") and not label.matches("motion_rms_all_mm_")
    with pytest.raises(ValueError):
        Column("a#b", "mm", "x")
    with pytest.raises(ValueError):
        Column("a", "mm", "two\tparts")


def test_no_column_name_means_two_things_across_the_tables():
    """A name in two dictionaries has one entry (unit and definition); no exact name of one
    table falls into a pattern of another."""
    entries: dict[str, Column] = {}
    for dictionary in DICTIONARIES.values():
        for column in dictionary:
            assert entries.setdefault(column.name, column) == column, column.name
    for name, column in entries.items():
        if column.is_pattern:
            continue
        hits = [p.name for p in entries.values() if p.is_pattern and p.matches(name)]
        assert hits == [], (name, hits)


def test_every_column_says_what_it_is_over():
    """The renamed quantities: the motion table's RMS values are over the unmasked vertices, the
    cohort's over all vertices (issue #19: motion_rms_mm meant both)."""
    names = {c.name for d in DICTIONARIES.values() for c in d}
    assert "motion_rms_mm" not in names and not any(n.startswith("motion_rms_mm_") for n in names)
    assert {"motion_rms_unmasked_mm", "noise_rms_unmasked_mm", "noise_relative_unmasked"} <= names
    assert {"motion_rms_all_mm_{label}", "noise_relative_unmasked_{label}"} <= names
    rms = [c for d in DICTIONARIES.values() for c in d if "rms" in c.name or c.name == "K={k}"]
    assert len(rms) >= 6
    for column in rms:  # an RMS says over which vertices (pixels)
        assert "RMS over" in column.definition, column.name


def test_accuracy_units_follow_their_names():
    for column in tables.ACCURACY:
        assert column.unit == tables.unit_from_name(column.name), column.name
    new = tables.accuracy_column("stereo_hole_share_max")
    assert new.unit == "fraction" and "accuracy.json" in new.definition
    assert tables.unit_from_name("mask.radius_mm") == "mm"
    assert tables.unit_from_name("smoothing.iterations") == "-"


def test_the_producers_columns_are_described():
    """What the stages put into their tables is in the dictionaries (the writer refuses the
    rest at run time)."""
    rng = np.random.default_rng(1)
    shapes = {n: rng.normal(size=(6, 3)) for n in ("neutral", "car", "too")}
    eigen, coefficients = pca_tables(pca(shapes))
    describe(pd.DataFrame(eigen).columns, tables.PCA_EIGENVALUES)
    describe(pd.DataFrame(coefficients).columns, tables.PCA_COEFFICIENTS)
    noise = ["take", *motion_noise.COLUMNS.values(), "click_noise_px_used"]
    assert [c.name for c in describe(noise, tables.MOTION_NOISE)] == noise
    describe(["take", *(f"q{i}" for i in range(1, 101))], tables.MODAL_COORDINATES)
    describe(["take", "K=1", "K=20", "K=100"], tables.MODAL_RECONSTRUCTION)


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o027, 0o640), (0o077, 0o600)])
def test_tables_honour_the_umask(tmp_path, umask, mode):
    old = os.umask(umask)
    try:
        write_table(tmp_path / "t.tsv", pd.DataFrame({"take": ["car"]}), tables.MOTION_NOISE)
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "t.tsv").stat().st_mode) == mode
    assert [p.name for p in tmp_path.iterdir()] == ["t.tsv"]  # no temporary left behind
