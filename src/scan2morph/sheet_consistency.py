"""Checks across a subject's sheet rows: a scan file serving two takes, a take id that names one
of the subject's model outputs, and the config's blends against the sheet's labels.

Each problem is one line naming the sheet row (:func:`scan2morph.sheet.sheet_problems` gathers
them with the rows' own problems; a take's problem leaves that take out).
"""

from __future__ import annotations

import os
import re
from collections.abc import Collection, Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pandas as pd

#: The columns that hold a take's own scan: one file may serve one take only (a calibration or
#: intrinsics file serves a whole rig, a landmark file may be copied on purpose, and meshes of
#: one head exported from a rig may share one texture map).
SCAN_COLUMNS = ("xyz", "color", "left", "right", "mesh", "depth")
#: Names of a subject's model outputs (``meshes/models/{name}.obj``, the glTF's morph targets)
#: that a take other than the neutral may not take: its own model would be overwritten.
MODEL_NAMES = ("neutral", "pca_mean")
_PCA_TARGET = re.compile(r"^pca_\d+_(pos|neg)$")


def blend_label_problem(blends: Mapping[str, Mapping], labels: Collection[str]) -> str | None:
    """The config's blends (``morph.blends``) naming a label that no take of the sheet has and
    that is not one of the paper's visemes: a misspelt label, found when the run starts rather
    than in every subject's job. None when every label is known."""
    from scan2morph.tol import VISEMES

    known = set(labels) | set(VISEMES)
    for name, weights in blends.items():
        unknown = [lab for lab in weights if lab not in known]
        if unknown:
            return (
                f"morph.blends.{name}: label {unknown[0]!r} is no take's label in the sheet "
                f"(labels: {sorted(set(labels))}; the paper's visemes: {list(VISEMES)})"
            )
    return None


def _where(rec) -> str:
    return f"{rec.sheet} row {rec.sheet_row} ({rec.subject}/{rec.take})"


def take_name_problems(rows: pd.DataFrame, reserved: Collection[str] = ()) -> list[tuple[str, str]]:
    """One subject's takes (other than its neutral) whose id names one of the subject's model
    outputs: the neutral's model, the PCA's mean or keys (:data:`MODEL_NAMES`, ``pca_{k}_pos``
    and ``_neg``) or a blend of the config (``reserved``). Their model would overwrite the other
    (``meshes/models/{name}.obj``, the glTF's morph target): each such take is left out.

    Returns
    -------
    list of (take, problem)
    """
    out = []
    for rec in rows.itertuples(index=False):
        if rec.kind == "neutral":
            continue
        if rec.take in MODEL_NAMES or _PCA_TARGET.match(rec.take):
            what = "a model of the subject's own (the neutral's, the PCA mean's or a PCA key's)"
        elif rec.take in reserved:
            what = "a blend of the config (morph.blends or morph.pca_blends)"
        else:
            continue
        out.append(
            (
                rec.take,
                f"{_where(rec)}: take id {rec.take!r} is also the name of {what}: one model would "
                f"overwrite the other (meshes/models/{rec.take}.obj, the glTF's morph target); "
                "rename the take",
            )
        )
    return out


def shared_scan_problems(rows: pd.DataFrame) -> list[tuple[str, str]]:
    """One subject's user rows whose scan file (:data:`SCAN_COLUMNS`) an earlier row of the
    subject names too: one scan cannot be two takes (a cell copied from another row). The later
    row's take is left out, its problem naming the earlier row. (Two subjects may share a scan:
    the same scans run twice, with other landmarks, to compare.)

    Returns
    -------
    list of (take, problem)
    """
    from scan2morph.sheet import MULTI_PATH_COLUMNS, split_paths  # the sheet imports this module

    seen: dict[str, str] = {}
    out: list[tuple[str, str]] = []
    for rec in rows.itertuples(index=False):
        if rec.synthetic:
            continue
        for col in SCAN_COLUMNS:
            value = getattr(rec, col, "") or ""
            parts = split_paths(value) if col in MULTI_PATH_COLUMNS else [value]
            for part in filter(None, parts):
                key = os.path.realpath(part)
                if key not in seen:
                    seen[key] = f"the {col} of row {rec.sheet_row} ({rec.take})"
                    continue
                out.append(
                    (
                        rec.take,
                        f"{_where(rec)}: column '{col}': {part} is also {seen[key]}: each take "
                        "needs its own scan (a cell copied from another row?)",
                    )
                )
    return out


__all__ = [
    "MODEL_NAMES",
    "SCAN_COLUMNS",
    "blend_label_problem",
    "shared_scan_problems",
    "take_name_problems",
]
