"""Where each dataset lives in a subject's store: the one place in code that spells store paths.

Every dataset of the store (``schemas/store.layout.yaml``) belongs to one group, and every group
to the one pipeline stage that writes it. The functions below build the paths; nothing else in
the library or the workflow writes a store path as a literal. :data:`DATASETS` lists every
dataset pattern with its writing stage; a test checks it against the layout file, and the
parameter sweeps derive from it which datasets a re-run stage replaces.

Paths are absolute HDF5 paths (``/takes/car/mesh/vertices``); ``{take}`` is a take id,
``{name}`` a blend name, ``{label}`` an expression label.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Container, Iterable

#: Pipeline stages in the order they run (each writes the datasets :data:`DATASETS` gives it).
STAGES = (
    "ingest",
    "repair",
    "landmarks",
    "fit",
    "align",
    "refine",
    "consensus",
    "motion",
    "motion_noise",
    "morph",
    "modal",
    "store",
)

#: (group pattern, writing stage, dataset names): a group may hold datasets of several stages.
_GROUPS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("/takes/{take}/raw", "ingest", ("xyz", "color")),
    ("/takes/{take}/range", "repair", ("xyz", "color", "spikes", "filled")),
    ("/takes/{take}", "ingest", ("clicks", "clicks_3d")),
    (
        "/takes/{take}",
        "landmarks",
        (
            "landmarks",
            "landmark_confidence",
            "landmark_source",
            "landmark_detector",
            "landmark_doubtful",
            "landmark_detected",
        ),
    ),
    (
        "/takes/{take}/camera",
        "ingest",
        ("modality", "model", "color_source", "K", "distortion", "pose", "size"),
    ),
    ("/template", "fit", ("faces", "vertices2d", "fiducials/names", "fiducials/indices")),
    ("/takes/{take}/mesh", "fit", ("vertices", "uv", "valid", "points2d", "noise_gain")),
    ("/takes/{take}/align", "align", ("transform", "vertices", "ok")),
    ("/takes/{take}/refine", "refine", ("vertices", "valid", "points2d", "confidence")),
    ("/takes/{take}/consensus", "consensus", ("vertices", "valid", "points2d", "correction")),
    ("/mask", "motion", ("suppressed", "seeds")),
    ("/neutral", "motion", ("vertices", "filled")),
    ("/neutral", "morph", ("head_frame",)),
    ("/visemes/{take}", "motion", ("motion_raw", "motion", "model")),
    ("/expressions/{take}", "motion", ("displacement",)),
    ("/visemes/{take}", "motion_noise", ("noise_rms_mm",)),
    (
        "/motion_noise",
        "motion_noise",
        (
            "takes",
            "relative",
            "rms_error_mm",
            "click_noise_px",
            "click_noise_measured_px",
            "stable_points",
            "failed_draws",
        ),
    ),
    (
        "/pca",
        "morph",
        (
            "mean",
            "components",
            "eigenvalues",
            "cr",
            "ccr",
            "coefficients",
            "takes",
            "sigma",
            "sigma_convention",
        ),
    ),
    ("/blends/{name}", "morph", ("vertices",)),
    ("/pca_blends/{name}", "morph", ("vertices",)),
    (
        "/modal",
        "modal",
        (
            "frequencies_hz",
            "modes",
            "dof_modes",
            "thickness_mm",
            "fixed_vertices",
            "outline_vertices",
            "outline_motion_mm",
            "reconstruction_k",
            "reconstruction_target_mm",
            "preset",
            "physics",
            "semantic/names",
            "semantic/modes",
        ),
    ),
    (
        "/expressions/{take}",
        "modal",
        (
            "coordinates",
            "reconstruction_rms_mm",
            "reconstruction_normal_rms_mm",
            "reconstruction_tangential_rms_mm",
            "modes_to_target",
            "outline_rms_mm",
            "clamped_rms_mm",
            "synthesized",
            "semantic_coordinates",
        ),
    ),
    ("/modal/statistics/{label}", "modal", ("mean", "std", "takes")),
    ("/warnings", "store", ("stage", "take", "message")),
    ("/failed/{take}", "ingest", ("stage", "reason")),
)
#: Groups written to parts only (the ingest part's raw images), never merged into the store.
PART_ONLY = ("/takes/{take}/raw",)

#: Every dataset pattern -> the stage that writes it.
DATASETS: dict[str, str] = {
    f"{group}/{name}": stage for group, stage, names in _GROUPS for name in names
}

TAKES = "/takes"
VISEMES = "/visemes"
EXPRESSIONS = "/expressions"
MOTION_NOISE = "/motion_noise"
#: The takes' consensus (its attributes: whether it was used, why not, which takes).
CONSENSUS = "/consensus"
MASK = "/mask"
PCA = "/pca"
BLENDS = "/blends"
PCA_BLENDS = "/pca_blends"
MODAL_STATISTICS = "/modal/statistics"
FIDUCIALS = "/template/fiducials"
FAILED = "/failed"
#: Group whose attributes name the stages a subject skipped (stage -> why).
SKIPPED = "/skipped"


def _check(name: str, allowed: Iterable[str], group: str) -> str:
    if name not in allowed:
        raise KeyError(f"{group}: no dataset {name!r} in the store layout (has {sorted(allowed)})")
    return name


def _build(group: str, dataset: str, **keys: str) -> str:
    allowed = {n for g, _, names in _GROUPS if g == group for n in names}
    return f"{group.format(**keys)}/{_check(dataset, allowed, group)}"


def take(take_id: str) -> str:
    """The group of one take (its attributes hold the sheet row, input checksums, reports)."""
    return f"{TAKES}/{take_id}"


def raw(take_id: str, name: str) -> str:
    """``xyz`` or ``color`` of a take as ingested (before repair; ingest parts only)."""
    return _build("/takes/{take}/raw", name, take=take_id)


def range_image(take_id: str, name: str) -> str:
    """``xyz``, ``color``, ``spikes`` or ``filled`` of a take's repaired range image."""
    return _build("/takes/{take}/range", name, take=take_id)


def landmarks(take_id: str) -> str:
    """A take's iBUG-68 landmarks (68, 2), 0-based pixels: the points the fit uses (clicked,
    detected or both; the dataset's attributes say which)."""
    return _build("/takes/{take}", "landmarks", take=take_id)


def landmark_confidence(take_id: str) -> str:
    """The detector's confidence (68,) in [0, 1] of each detected landmark (NaN: clicked)."""
    return _build("/takes/{take}", "landmark_confidence", take=take_id)


def landmark_info(take_id: str, name: str) -> str:
    """What a take's landmarks are: ``source`` (``clicked``, ``detected`` or ``clicked+detected
    jawline``), ``detector`` (its name and version; empty when all are clicked) and ``doubtful``
    (why the detection is doubtful; empty when it is not)."""
    return _build("/takes/{take}", f"landmark_{name}", take=take_id)


def landmark_detected(take_id: str) -> str:
    """A detected take's landmarks as the detector placed them (68, 2) px, before a doubtful
    detection's mouth, brows and chin went onto the lips, the eyebrows and the face's outline and
    its stable points were carried over from the neutral (what the click precision is measured
    on)."""
    return _build("/takes/{take}", "landmark_detected", take=take_id)


def clicks(take_id: str) -> str:
    """A take's landmarks as its landmark file gives them (68, 2), 0-based pixels; NaN rows for
    the points a 51-point file leaves out. Absent for a take without a landmark file."""
    return _build("/takes/{take}", "clicks", take=take_id)


def clicks_3d(take_id: str) -> str:
    """A mesh take's landmarks as its landmark file gives them (68, 3), mm in the mesh's frame;
    NaN rows for the points a 51-point file leaves out. Absent for other takes and for a mesh
    take without a landmark file."""
    return _build("/takes/{take}", "clicks_3d", take=take_id)


def camera(take_id: str, name: str) -> str:
    """Provenance of a take's pixel grid: ``modality`` (``range``, ``stereo``, ``mesh``,
    ``rgbd``), ``model`` (which camera, real or virtual), for mesh takes ``color_source``
    (``texture``, ``vertex colours`` or ``shading``: geometry only; also ``shading`` for a range
    take without a colour image, ``texture shot`` for a stereo take with one), and for mesh and
    RGB-D takes that
    camera's ``K`` (3, 3) px, ``distortion`` (5,), ``pose`` (4, 4) take frame -> camera, mm,
    and image ``size`` (width, height) px."""
    return _build("/takes/{take}/camera", name, take=take_id)


def template(name: str) -> str:
    """``faces``, ``vertices2d``, ``fiducials/names`` or ``fiducials/indices``."""
    return _build("/template", name)


def mesh(take_id: str, name: str) -> str:
    """``vertices``, ``uv``, ``valid`` or ``points2d`` of a take's fitted mesh."""
    return _build("/takes/{take}/mesh", name, take=take_id)


def align_group(take_id: str) -> str:
    """The alignment group of a take (its attributes hold the ICP quality)."""
    return f"{take(take_id)}/align"


def align(take_id: str, name: str) -> str:
    """``transform``, ``vertices`` or ``ok`` (passed its quality gate) of a take's rigid
    alignment to the neutral."""
    return _build("/takes/{take}/align", name, take=take_id)


def refine_group(take_id: str) -> str:
    """The refinement group of a take (its attributes hold the correction's statistics)."""
    return f"{take(take_id)}/refine"


def refine(take_id: str, name: str) -> str:
    """``vertices`` (neutral frame), ``valid``, ``points2d`` or ``confidence`` of a take's
    correspondence refined by image correlation."""
    return _build("/takes/{take}/refine", name, take=take_id)


def consensus_group(take_id: str) -> str:
    """The takes' consensus group of a take (its attributes hold the move's statistics)."""
    return f"{take(take_id)}/consensus"


def consensus(take_id: str, name: str) -> str:
    """``vertices`` (neutral frame), ``valid``, ``points2d`` or ``correction`` (px) of a take's
    refined correspondence moved onto the skin points the subject's takes agree on."""
    return _build("/takes/{take}/consensus", name, take=take_id)


def refined(take_id: str, keys: Container[str]) -> Callable[[str, str], str]:
    """The group of a take's refined correspondence among ``keys`` (the store's, or a mapping
    of parts): :func:`consensus` where the takes' consensus moved it, else :func:`refine`."""
    return consensus if consensus(take_id, "vertices") in keys else refine


def mask(name: str) -> str:
    """``suppressed`` or ``seeds`` of the stencil mask."""
    return _build(MASK, name)


def neutral(name: str) -> str:
    """``vertices`` or ``filled`` of the base model S_0, or its ``head_frame`` (the glTF's frame:
    neutral frame mm -> head frame m, written by morph)."""
    return _build("/neutral", name)


def viseme(take_id: str, name: str) -> str:
    """``motion_raw``, ``motion``, ``model`` or ``noise_rms_mm`` of a viseme take."""
    return _build("/visemes/{take}", name, take=take_id)


def expression(take_id: str, name: str) -> str:
    """``displacement``, ``coordinates``, ``reconstruction_rms_mm`` (and its
    ``reconstruction_normal_rms_mm`` / ``reconstruction_tangential_rms_mm`` parts),
    ``modes_to_target``, ``outline_rms_mm``, ``clamped_rms_mm``, ``synthesized`` or
    ``semantic_coordinates`` of an expression take."""
    return _build("/expressions/{take}", name, take=take_id)


def motion_noise(name: str) -> str:
    """A dataset of the click-noise error bar (``takes``, ``relative``, ``rms_error_mm``, ...)."""
    return _build(MOTION_NOISE, name)


def pca(name: str) -> str:
    """``mean``, ``components``, ``eigenvalues``, ``cr``, ``ccr``, ``coefficients``, ``takes``,
    ``sigma`` or ``sigma_convention``."""
    return _build(PCA, name)


def blend(name: str) -> str:
    """The vertices of a named blend shape."""
    return _build(BLENDS + "/{name}", "vertices", name=name)


def pca_blend(name: str) -> str:
    """The vertices of a named PCA blend."""
    return _build(PCA_BLENDS + "/{name}", "vertices", name=name)


def modal(name: str) -> str:
    """A dataset of the modal basis (``frequencies_hz``, ``modes``, ``semantic/names``, ...)."""
    return _build("/modal", name)


def modal_statistics(label: str, name: str) -> str:
    """``mean``, ``std`` or ``takes`` of the modal coordinates of one expression label."""
    return _build(MODAL_STATISTICS + "/{label}", name, label=label)


def warnings(name: str) -> str:
    """``stage``, ``take`` or ``message`` of the subject's warnings (one entry per warning)."""
    return _build("/warnings", name)


def failed(take_id: str, name: str) -> str:
    """``stage`` or ``reason`` of a take left out of its subject (the stage that refused it and
    its message). Written by whichever per-take stage failed; listed here under ``ingest``, the
    first of them."""
    return _build("/failed/{take}", name, take=take_id)


def _regex(pattern: str) -> str:
    parts = re.split(r"(\{[a-z_]+\})", pattern)
    return "".join("[^/]+" if p.startswith("{") else re.escape(p) for p in parts)


def written_by(stages: Iterable[str]) -> re.Pattern:
    """A regular expression matching every store path that one of ``stages`` writes."""
    stages = set(stages)
    unknown = stages - set(STAGES)
    if unknown:
        raise KeyError(f"unknown stages {sorted(unknown)}; stages are {STAGES}")
    patterns = [_regex(p) for p, s in DATASETS.items() if s in stages]
    return re.compile("^(" + "|".join(patterns) + ")$" if patterns else "(?!)")


def ids(keys: Iterable[str], root: str, dataset: str) -> list[str]:
    """The ids (take ids, blend names) under ``root`` that hold ``dataset``, in key order.

    Parameters
    ----------
    keys : iterable of str
        Store paths (a part's or store's keys).
    root : str
        :data:`TAKES`, :data:`VISEMES`, :data:`EXPRESSIONS`, ...
    dataset : str
        The dataset below the id (``mesh/vertices``, ``model``).
    """
    rx = re.compile(f"^{re.escape(root)}/([^/]+)/{re.escape(dataset)}$")
    return list(dict.fromkeys(m.group(1) for k in keys if (m := rx.match(k))))
