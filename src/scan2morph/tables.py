"""Every table the pipeline writes (TSV), each with its column dictionary at the top.

One writer, :func:`write_table`, serves every table: ``results/{subject}/tables/motion_noise.tsv``,
``pca_eigenvalues.tsv``, ``pca_coefficients.tsv``, ``modal_coordinates.tsv``,
``modal_reconstruction.tsv``, ``results/cohort/summary.tsv`` and ``results/sweeps/summary.tsv``.
The file starts with the dictionary as comment lines, then the table::

    # column	unit	definition
    # take	-	take id, as in the subject sheet (config/subjects.tsv)
    # w{k}	mm	coefficient of the shape on principal component k: ...
    take	w1	w2
    neutral	-97.5	68.5

``pandas.read_csv(path, sep="\\t", comment="#")`` (or :func:`read_table`) reads the table,
:func:`read_dictionary` the dictionary. Columns that come in families are described once, by a
pattern with one ``{placeholder}`` (``w{k}``, ``K={k}``, ``motion_rms_all_mm_{label}``); ``{k}``
stands for a positive integer, any other placeholder for any non-empty text.

Names say what a number is over (``motion_rms_unmasked_mm``: over the vertices outside the
stencil mask; ``motion_rms_all_mm_{label}``: over all vertices), and one name means one thing
in every table (``tests/unit/test_tables.py`` checks the dictionaries against each other).
"""

from __future__ import annotations

import io
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from scan2morph.errors import InputError, writing
from scan2morph.jobs import atomic_output

#: First comment line of every table: the dictionary's own header.
HEADER = ("column", "unit", "definition")
#: Unit of a column that is no quantity (an id or a name).
NO_UNIT = "-"


@dataclass(frozen=True)
class Column:
    """One entry of a column dictionary.

    Attributes
    ----------
    name : str
        The column's name, or a pattern with one ``{placeholder}`` for a family of columns.
    unit : str
        ``mm``, ``mm^2``, ``deg``, ``px``, ``Hz``, ``fraction``, ``count``, ... or ``-``.
    definition : str
        What the number is, over what, and where it comes from (one line, no tab).
    """

    name: str
    unit: str
    definition: str

    def __post_init__(self):
        for field in (self.name, self.unit, self.definition):
            if not field or "\t" in field or "\n" in field:
                raise ValueError(f"column dictionary entry {self}: empty, or a tab or newline")
        if "#" in self.name:  # pandas' comment="#" would cut the table's header there
            raise ValueError(f"column name {self.name!r}: no # allowed")

    @property
    def is_pattern(self) -> bool:
        return "{" in self.name

    @property
    def regex(self) -> re.Pattern:
        """The names this entry describes."""
        out, pos = [], 0
        for m in re.finditer(r"\{(\w+)\}", self.name):
            out.append(re.escape(self.name[pos : m.start()]))
            out.append(r"[1-9][0-9]*" if m.group(1) == "k" else r".+")
            pos = m.end()
        out.append(re.escape(self.name[pos:]))
        return re.compile("".join(out))

    def matches(self, column: str) -> bool:
        return self.regex.fullmatch(column) is not None


def unit_from_name(name: str) -> str:
    """The unit a column or metric name states by its parts (``_mm``, ``_deg``, ``_px``,
    ``_hz``; ``relative``, ``share``, ``coverage``, ``ccr``, ``cr``: a fraction); ``-`` when
    the name states none."""
    parts = set(re.split(r"[._]", name.lower()))
    for token, unit in (("mm", "mm"), ("deg", "deg"), ("px", "px"), ("hz", "Hz")):
        if token in parts:
            return unit
    if parts & {"relative", "share", "coverage", "ccr", "cr", "fraction"}:
        return "fraction"
    return NO_UNIT


# --- columns shared by several tables (one name, one meaning) ---
TAKE = Column("take", NO_UNIT, "take id, as in the subject sheet (config/subjects.tsv)")
SUBJECT = Column("subject", NO_UNIT, "subject id, as in the subject sheet or the synthetic cohort")
CLICK_NOISE_USED = Column(
    "click_noise_px_used",
    "px",
    "the click noise the subject's error bar used: standard deviation per image coordinate of "
    "the landmark perturbation of its refits, measured from the stable landmarks or configured "
    "(motion_noise.click_noise_px); store /motion_noise/click_noise_px",
)

#: ``results/{subject}/tables/motion_noise.tsv``: one row per viseme take in the models.
MOTION_NOISE = (
    TAKE,
    Column(
        "motion_rms_unmasked_mm",
        "mm",
        "RMS over the vertices outside the stencil mask (/mask/suppressed) of the length of the "
        "take's final motion from its own clicks (/visemes/{take}/motion)",
    ),
    Column(
        "noise_rms_unmasked_mm",
        "mm",
        "click-noise error of that motion: RMS over the vertices outside the stencil mask of "
        "/visemes/{take}/noise_rms_mm (per vertex: RMS over the refits with perturbed landmarks "
        "of the change of the final motion); store /motion_noise/rms_error_mm",
    ),
    Column(
        "noise_relative_unmasked",
        "fraction",
        "noise_rms_unmasked_mm / motion_rms_unmasked_mm (both over the vertices outside the "
        "mask): the click-noise error bar of the motion; store /motion_noise/relative",
    ),
    Column(
        "failed_draws",
        "count",
        "refits of the take or of the neutral (of motion_noise.draws) refused and left out "
        "(folded template, a fiducial outside the image)",
    ),
    CLICK_NOISE_USED,
)

#: ``results/{subject}/tables/pca_eigenvalues.tsv`` (the paper's Table 1): one row per component.
PCA_EIGENVALUES = (
    Column("component", NO_UNIT, "principal component number, 1 = largest eigenvalue"),
    Column(
        "eigenvalue",
        "mm^2",
        "eigenvalue of C = X'X'^T (no 1/M) over the M shapes (neutral and viseme models, all "
        "vertex coordinates): the sum over the shapes of the squared coefficient w{k}",
    ),
    Column("cr", "fraction", "contribution rate: eigenvalue / sum of all eigenvalues"),
    Column(
        "ccr",
        "fraction",
        "cumulative contribution rate: sum of cr over the components 1 .. component",
    ),
    Column(
        "sigma_sample_mm",
        "mm",
        "the unit of Eq. 2's alpha on this component (morph.sigma: sample): sample standard "
        "deviation over the M shapes of their coefficient w{k}, sqrt(eigenvalue / (M - 1))",
    ),
    Column(
        "sigma_paper_mm",
        "mm",
        "the unit of Eq. 2's alpha on this component (morph.sigma: paper): sqrt(eigenvalue), "
        "as printed in the paper",
    ),
)

#: ``results/{subject}/tables/pca_coefficients.tsv`` (the paper's Table 2): one row per shape.
PCA_COEFFICIENTS = (
    TAKE,
    Column(
        "w{k}",
        "mm",
        "coefficient of the take's shape (the neutral or a viseme model) on principal component "
        "k: the unit-norm component (a 3V vector over all vertices) dotted with shape - mean",
    ),
)

#: ``results/{subject}/tables/modal_coordinates.tsv``: one row per expression take.
MODAL_COORDINATES = (
    TAKE,
    Column(
        "q{k}",
        "mm*t^0.5",
        "modal coordinate of the expression's displacement field (all vertices) on vector k of "
        "the natural basis (in the natural modes' order, ascending frequency): q = Q^T W v, v "
        "in mm, W-orthonormal vectors Q, W in tonnes as the store's /modal/physics coordinates "
        "says: 'mass', the FEM mass matrix (paper Eq. 7); 'vertex' (the skin preset), the "
        "model's mass shared equally by the vertices, the natural modes orthonormalised in "
        "order in it (the least-squares fit on the first K, uniform weight per vertex); store "
        "/expressions/{take}/coordinates",
    ),
)

#: ``results/{subject}/tables/modal_reconstruction.tsv``: three rows per expression take (the
#: error's total, its normal and its tangential part).
MODAL_RECONSTRUCTION = (
    TAKE,
    Column(
        "part",
        NO_UNIT,
        "total: the error vector's length; normal: its component along the neutral's vertex "
        "normal (a wrong surface, what bending modes rebuild); tangential: its part along the "
        "surface (sliding); total^2 = normal^2 + tangential^2",
    ),
    Column(
        "K={k}",
        "mm",
        "RMS over all vertices of that part of the error of the expression's displacement "
        "rebuilt from its lowest k modal coordinates; store "
        "/expressions/{take}/reconstruction_rms_mm (total), reconstruction_normal_rms_mm, "
        "reconstruction_tangential_rms_mm",
    ),
    Column(
        "modes_to_target",
        "count",
        "fewest lowest modes whose total RMS error is at most modal.target_rms_mm "
        "(/modal/reconstruction_target_mm); 0 when the expression itself moves less; NA when "
        "no K of the basis reaches it; store "
        "/expressions/{take}/modes_to_target",
    ),
)

#: The accuracy summary of ``accuracy.json`` (synthetic subjects, against ground truth), as
#: columns of the cohort and sweep summaries. Unknown metrics: :func:`accuracy_column`.
ACCURACY = (
    Column(
        "mesh_rms_mm_max",
        "mm",
        "largest over the takes of the RMS over a take's valid fitted vertices of their "
        "distance to the true surface",
    ),
    Column(
        "align_rotation_deg_max",
        "deg",
        "largest over the takes other than the neutral of the rotation error of the alignment",
    ),
    Column(
        "align_translation_mm_max",
        "mm",
        "largest over the takes other than the neutral of the alignment's translation error at "
        "the centroid of the take's valid vertices",
    ),
    Column(
        "motion_relative_error_max",
        "fraction",
        "largest over the visemes of the RMS over the unmasked vertices of the final motion "
        "minus the ideal motion (through the same mask and smoothing), over the RMS of that "
        "ideal motion there",
    ),
    Column(
        "motion_normal_relative_error_max",
        "fraction",
        "largest over the visemes of the part of that error along the neutral's surface normal "
        "(RMS over the unmasked vertices with a normal), over the same reference",
    ),
    Column(
        "motion_material_relative_error_max",
        "fraction",
        "largest over the visemes of the RMS over the unmasked vertices of the final motion "
        "minus the true material motion, over the RMS of the material motion there",
    ),
    Column(
        "expression_material_relative_error_max",
        "fraction",
        "largest over the expressions of the RMS over all vertices of the displacement field "
        "minus the true material motion, over the RMS of the material motion",
    ),
    Column(
        "masked_true_motion_share_max",
        "fraction",
        "largest over the visemes of the share of the material motion's energy (sum over all "
        "vertices of squared lengths) on the vertices the stencil mask suppresses",
    ),
    Column(
        "motion_click_noise_relative_max",
        "fraction",
        "largest over the visemes of noise_relative_unmasked (tables/motion_noise.tsv)",
    ),
    Column(
        "click_noise_px_true",
        "px",
        "true click scatter: RMS over the stable landmarks of the neutral and the visemes and "
        "both image coordinates of clicked minus exact landmark",
    ),
    Column(
        "click_noise_px_measured",
        "px",
        "click noise the pipeline measured on the stable landmarks (NA: too few to compare)",
    ),
    CLICK_NOISE_USED,
    Column(
        "stereo_depth_rms_mm_max",
        "mm",
        "largest over the stereo takes of the RMS over the face pixels with data of the depth "
        "error along the pixel's ray",
    ),
    Column(
        "stereo_coverage_min",
        "fraction",
        "smallest over the stereo takes of the share of the face pixels with data",
    ),
)

#: ``results/cohort/summary.tsv``: one row per subject (accuracy columns: :data:`ACCURACY`).
COHORT = (
    SUBJECT,
    Column("n_takes", "count", "takes of the subject in its store"),
    Column("n_visemes", "count", "viseme takes"),
    Column("n_expressions", "count", "expression takes"),
    Column(
        "left_out",
        NO_UNIT,
        "takes left out of the subject, each as take (stage that refused it), '; '-separated, "
        "NA when none (the tables' missing value); the reasons are in the subject's store (/failed) and at the top of "
        "its report",
    ),
    Column(
        "stopped",
        NO_UNIT,
        "why the subject did not finish in the run that wrote the table (its check or one of "
        "its jobs stopped it; its other columns are then NA), NA when it finished",
    ),
    Column(
        "material_relative_error_viseme_{label}",
        "fraction",
        "error of a viseme's final motion against the material motion of the skin (where each "
        "skin point really went): RMS over the unmasked vertices of the difference, over the RMS "
        "of the material motion there; accuracy.json takes.{take}.motion.material_relative_error, "
        "mean over the label's viseme takes (synthetic subjects)",
    ),
    Column(
        "material_rms_error_mm_viseme_{label}",
        "mm",
        "RMS over the unmasked vertices of the length of that error; accuracy.json "
        "material_rms_error_mm, mean over the label's viseme takes",
    ),
    Column(
        "material_normal_rms_error_mm_viseme_{label}",
        "mm",
        "its part along the neutral's vertex normal (a wrong surface): RMS over the unmasked "
        "vertices; accuracy.json material_normal_rms_error_mm, mean over the label's viseme takes",
    ),
    Column(
        "material_tangential_rms_error_mm_viseme_{label}",
        "mm",
        "its part along the surface (skin that slid): RMS over the unmasked vertices of its "
        "length; accuracy.json material_tangential_rms_error_mm, mean over the label's viseme "
        "takes",
    ),
    Column(
        "ideal_relative_error_viseme_{label}",
        "fraction",
        "the second figure: error against the method-ideal motion (what exact clicks would give, "
        "through the same mask and smoothing), RMS over the unmasked vertices over the RMS of "
        "that motion; accuracy.json relative_error, mean over the label's viseme takes",
    ),
    Column(
        "material_relative_error_expression_{label}",
        "fraction",
        "error of an expression's displacement field (/expressions/{take}/displacement) against "
        "the material motion of the skin: RMS over all vertices of the difference, over the RMS "
        "of the material motion; accuracy.json takes.{take}.expression.material_relative_error, "
        "mean over the label's expression takes",
    ),
    Column(
        "material_rms_error_mm_expression_{label}",
        "mm",
        "RMS over all vertices of the length of that error; accuracy.json material_rms_error_mm, "
        "mean over the label's expression takes",
    ),
    Column(
        "material_normal_rms_error_mm_expression_{label}",
        "mm",
        "its part along the neutral's vertex normal: RMS over all vertices; accuracy.json "
        "material_normal_rms_error_mm, mean over the label's expression takes",
    ),
    Column(
        "material_tangential_rms_error_mm_expression_{label}",
        "mm",
        "its part along the surface (sliding): RMS over all vertices of its length; "
        "accuracy.json material_tangential_rms_error_mm, mean over the label's expression takes",
    ),
    Column(
        "motion_rms_all_mm_{label}",
        "mm",
        "RMS over all template vertices with a value (the masked ones, which do not move, "
        "included) of the length of the final motion of a viseme take with that label "
        "(/visemes/{take}/motion), mean over the label's takes",
    ),
    Column(
        "noise_relative_unmasked_{label}",
        "fraction",
        "noise_relative_unmasked of tables/motion_noise.tsv (over the vertices outside the "
        "mask), mean over the viseme takes with that label",
    ),
    Column(
        "ccr_{k}",
        "fraction",
        "cumulative contribution rate of the first k principal components (ccr of "
        "tables/pca_eigenvalues.tsv); NA when the PCA has fewer components",
    ),
    Column("modal_f1_hz", "Hz", "lowest natural frequency of the subject's modal basis"),
)

_KNOWN_ACCURACY = {c.name: c for c in ACCURACY}


def accuracy_column(name: str) -> Column:
    """The dictionary entry of an accuracy summary metric; a metric without one of its own gets
    its unit from its name (:func:`unit_from_name`)."""
    if name in _KNOWN_ACCURACY:
        return _KNOWN_ACCURACY[name]
    return Column(
        name,
        unit_from_name(name),
        f"accuracy summary value {name} of accuracy.json (against ground truth; _max: largest, "
        "_min: smallest over the takes)",
    )


#: The sweep summary's column saying why a combination's stages refused the subject
#: (:func:`scan2morph.sweep.combination_accuracy`; NA when they did not).
REFUSED = "refused"


def sweep_dictionary(
    params: Sequence[str], metrics: Iterable[str], defaults: Mapping[str, object] | None = None
) -> tuple[Column, ...]:
    """The dictionary of ``results/sweeps/summary.tsv``: the swept config keys, ``subject``
    and the accuracy metrics (one row per combination and synthetic subject)."""
    defaults = defaults or {}
    swept = []
    for p in params:
        default = f"; the config's value: {defaults[p]}" if p in defaults else ""
        swept.append(
            Column(
                p,
                unit_from_name(p),
                f"value of the config key {p} in this combination "
                f"(schemas/config.schema.yaml){default}",
            )
        )
    refused = Column(
        REFUSED,
        NO_UNIT,
        "why the combination's stages refused the subject (its metrics are then NA); NA when "
        "they did not",
    )
    return (*swept, SUBJECT, *(accuracy_column(m) for m in metrics), refused)


def describe(columns: Iterable[str], dictionary: Sequence[Column]) -> list[Column]:
    """The entries of ``dictionary`` that describe ``columns``, in dictionary order.

    A name equal to an entry's name takes that entry; otherwise exactly one pattern must match.

    Raises
    ------
    ValueError
        A column the dictionary does not describe, or describes twice.
    """
    exact = {c.name: c for c in dictionary if not c.is_pattern}
    patterns = [c for c in dictionary if c.is_pattern]
    used: set[str] = set()
    for column in columns:
        if column in exact:
            used.add(column)
            continue
        hits = [c.name for c in patterns if c.matches(str(column))]
        if len(hits) != 1:
            why = "no entry" if not hits else f"two entries ({', '.join(hits)})"
            raise ValueError(f"column {column!r}: {why} in the column dictionary")
        used.add(hits[0])
    return [c for c in dictionary if c.name in used]


def dictionary_text(entries: Sequence[Column]) -> str:
    """The dictionary as comment lines: ``# column<TAB>unit<TAB>definition``, one per entry."""
    lines = [HEADER, *((c.name, c.unit, c.definition) for c in entries)]
    return "".join("# " + "\t".join(line) + "\n" for line in lines)


def write_table(
    path: str | Path,
    table: pd.DataFrame,
    dictionary: Sequence[Column],
    *,
    float_format: str = "%.6g",
    na_rep: str = "NA",
) -> list[Column]:
    """Write ``table`` as TSV (no index) with its column dictionary as header comment lines.

    Parameters
    ----------
    path : str or Path
        The ``.tsv`` written (replaced atomically, mode from the user's umask).
    table : DataFrame
        Every column must be described by ``dictionary`` (see :func:`describe`).
    dictionary : sequence of Column
        Only the entries describing a column of ``table`` are written.

    Returns
    -------
    list of Column
        The entries written.
    """
    entries = describe(table.columns, dictionary)
    body = io.StringIO()
    table.to_csv(body, sep="\t", index=False, float_format=float_format, na_rep=na_rep)
    with atomic_output(path) as tmp, writing(path):
        tmp.write_text(dictionary_text(entries) + body.getvalue(), encoding="utf-8")
    return entries


def read_table(path: str | Path, **kwargs) -> pd.DataFrame:
    """A table written by :func:`write_table` (its dictionary skipped): ``pandas.read_csv``
    with ``sep="\\t"`` and ``comment="#"``; keyword arguments go to it."""
    return pd.read_csv(path, sep="\t", comment="#", **kwargs)


def read_dictionary(path: str | Path) -> pd.DataFrame:
    """The column dictionary at the top of a table: columns ``column``, ``unit``,
    ``definition``, one row per entry.

    Raises
    ------
    InputError
        The file does not start with a dictionary.
    """
    lines = []
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            if not line.startswith("# "):
                break
            lines.append(line[2:])
    if not lines or lines[0].rstrip("\n").split("\t") != list(HEADER):
        raise InputError(path, "no column dictionary (# column<TAB>unit<TAB>definition) on top")
    return pd.read_csv(io.StringIO("".join(lines)), sep="\t", dtype=str, keep_default_na=False)


__all__ = [
    "ACCURACY",
    "COHORT",
    "MODAL_COORDINATES",
    "MODAL_RECONSTRUCTION",
    "MOTION_NOISE",
    "PCA_COEFFICIENTS",
    "PCA_EIGENVALUES",
    "Column",
    "accuracy_column",
    "describe",
    "dictionary_text",
    "read_dictionary",
    "read_table",
    "sweep_dictionary",
    "unit_from_name",
    "write_table",
]
