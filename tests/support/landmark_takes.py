"""Synthetic takes on their pixel grids, as the pipeline sees them, with their landmark truth.

Takes of the default synthetic cohort (config/config.yaml ``synthetic``: seed 2009, range,
stereo, mesh and RGB-D subjects) are written by the synth stage, read by the ingest stage and
repaired by the repair stage; the truth is the exact projection of the generator's 3D landmarks
(``truth/{take}.npz``), for a mesh take through the ingest's virtual camera. Used by
``tests/unit/test_landmarks.py`` and ``benchmarks/bench_landmarks.py``. The detector was
trained on other identities (other seeds): these takes are held out.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scan2morph.sheet import input_roles, synthetic_rows
from scan2morph.stages import ingest, repair, synth
from scan2morph.stages.part import Take
from scan2morph.store import paths
from tests.support.configs import repo_config


@dataclass(frozen=True)
class GridTake:
    """One take after ingest and repair.

    Attributes
    ----------
    subject, take, label, modality : str
    color : (H, W, 3) uint8
    xyz : (H, W, 3) float32, mm (NaN = no surface)
    truth : (68, 2) float64, px
    """

    subject: str
    take: str
    label: str
    modality: str
    color: np.ndarray
    xyz: np.ndarray
    truth: np.ndarray


def _rows(config: dict, root: Path):
    syn = config["synthetic"]
    return synthetic_rows(
        syn["subjects"],
        syn["prefix"],
        syn["takes"],
        str(root),
        stereo=syn.get("stereo"),
        mesh=syn.get("mesh"),
        rgbd=syn.get("rgbd"),
    )


def _write_subject(rows, config: dict, root: Path) -> None:
    """Write a subject's takes (the rows given) with the synth stage."""
    subject = rows[0]["subject"]
    (root / subject / "truth").mkdir(parents=True, exist_ok=True)
    params = synth.Params.from_config(config)
    for r in rows:
        files = {
            role: r["color" if role == "rgbd_color" else role]
            for role in synth.ROLES[r["modality"]]
        }
        files["landmarks"] = r["landmarks"]
        files["truth"] = str(root / subject / "truth" / f"{r['take']}.npz")
        part = synth.run(None, Take.from_row(r), params)
        synth.write_files(part, files)


def _grid(row, config: dict, root: Path) -> GridTake:
    """Ingest and repair one written take; its truth on the grid."""
    take, subject = row["take"], row["subject"]
    files = {role: row[role] for role in input_roles(row)} | {"landmarks": row["landmarks"]}
    part = ingest.run(None, Take.from_row(row, files=files), ingest.Params.from_config(config))
    attrs = part.attrs[paths.take(take)]
    raw = Take.from_row(row, data=part.datasets, attrs=attrs)
    fixed = repair.run(None, raw, repair.Params.from_config(config))
    data = fixed.datasets
    with np.load(root / subject / "truth" / f"{take}.npz") as z:
        if row["modality"] == "mesh":
            K = part.datasets[paths.camera(take, "K")]
            pose = part.datasets[paths.camera(take, "pose")]
            cam = z["landmarks3d"] @ pose[:3, :3].T + pose[:3, 3]
            uvw = cam @ K.T
            truth = uvw[:, :2] / uvw[:, 2:]
        else:
            truth = np.array(z["landmarks2d"])
    return GridTake(
        subject,
        take,
        row["label"],
        row["modality"],
        np.asarray(data[paths.range_image(take, "color")]),
        np.asarray(data[paths.range_image(take, "xyz")]),
        truth,
    )


def cohort_takes(
    root: Path, picks: list[tuple[str, str]] | None = None, config: dict | None = None
) -> list[GridTake]:
    """Takes of the default synthetic cohort on their grids.

    Parameters
    ----------
    root : Path
        Working folder for the written inputs.
    picks : list of (subject, take), optional
        Only these takes (default: every take of the cohort).
    config : dict, optional
        Default: config/config.yaml.

    Returns
    -------
    list of GridTake
    """
    config = config or repo_config()
    rows = _rows(config, root).to_dict("records")
    if picks is not None:
        rows = [r for r in rows if (r["subject"], r["take"]) in set(picks)]
    out = []
    for subject in dict.fromkeys(r["subject"] for r in rows):
        mine = [r for r in rows if r["subject"] == subject]
        _write_subject(mine, config, root)
        out += [_grid(r, config, root) for r in mine]
    return out
