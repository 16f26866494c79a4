"""Provenance of a subject's results: store attributes, software versions, run time per stage.

Run times come from the benchmark files Snakemake's ``benchmark:`` directive writes, one TSV per
job under ``{root}/{rule}/{subject}.tsv`` (subject-level jobs) or ``{root}/{rule}/{subject}/*.tsv``
(one per take); their column ``s`` is the job's wall-clock time in seconds.
"""

from __future__ import annotations

import json
import platform
import sys
from collections.abc import Iterable
from pathlib import Path

import h5py
import pandas as pd

from scan2morph.errors import InputError
from scan2morph.provenance import distribution_version

#: The dependencies whose versions a report lists (display name -> distribution names tried).
DEPENDENCIES: dict[str, tuple[str, ...]] = {
    "numpy": ("numpy",),
    "scipy": ("scipy",),
    "open3d": ("open3d", "open3d-cpu"),
    "opencv": (
        "opencv-contrib-python-headless",
        "opencv-contrib-python",
        "opencv-python-headless",
        "opencv-python",
    ),
    "h5py": ("h5py",),
    "snakemake": ("snakemake",),
    "pyrender": ("pyrender",),
    "pyfe3d": ("pyfe3d",),
    "trimesh": ("trimesh",),
    "matplotlib": ("matplotlib",),
    "pandas": ("pandas",),
}

#: Root attributes of the store shown as provenance (docs/outputs.md).
STORE_ATTRIBUTES = (
    "subject",
    "format_version",
    "scan2morph_version",
    "config_sha256",
    "units",
    "code_sha256",
    "git_commit",
    "git_dirty",
)


def software_versions(dependencies: dict[str, tuple[str, ...]] | None = None) -> dict[str, str]:
    """Python, platform, scan2morph and dependency versions of the running interpreter.

    Parameters
    ----------
    dependencies : dict, optional
        Display name -> distribution names tried in order; default :data:`DEPENDENCIES`.

    Returns
    -------
    dict
        Name -> version string (``"not installed"`` for a missing dependency), in order: python,
        platform, scan2morph, then the dependencies.
    """
    deps = DEPENDENCIES if dependencies is None else dependencies
    out = {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "scan2morph": distribution_version(("scan2morph",)) or "not installed",
    }
    for name, dists in deps.items():
        out[name] = distribution_version(dists) or "not installed"
    return out


def store_provenance(h5: h5py.File) -> tuple[dict[str, str], dict[str, dict[str, str]]]:
    """The store's identifying root attributes and its input checksums.

    Parameters
    ----------
    h5 : h5py.File
        An open subject store.

    Returns
    -------
    attributes : dict
        :data:`STORE_ATTRIBUTES` present in the file, as strings.
    checksums : dict
        take -> role (``xyz``, ``color``, ``landmarks``, ``left`` ...) -> SHA-256 hex digest.

    Raises
    ------
    InputError
        ``input_sha256`` is not a JSON object of objects.
    """
    attrs = {}
    for key in STORE_ATTRIBUTES:
        if key in h5.attrs:
            value = h5.attrs[key]
            attrs[key] = value.decode() if isinstance(value, bytes) else str(value)
    raw = h5.attrs.get("input_sha256", "{}")
    raw = raw.decode() if isinstance(raw, bytes) else str(raw)
    try:
        checksums = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise InputError(h5.filename, f"root attribute input_sha256: not JSON ({exc})") from exc
    if not isinstance(checksums, dict) or not all(isinstance(v, dict) for v in checksums.values()):
        raise InputError(
            h5.filename, "root attribute input_sha256: expected a JSON object take -> role -> hash"
        )
    return attrs, {t: {r: str(h) for r, h in roles.items()} for t, roles in checksums.items()}


def _benchmark_seconds(path: Path) -> tuple[float, float]:
    table = pd.read_csv(path, sep="\t")
    if "s" not in table.columns or table.empty:
        raise InputError(path, "benchmark file: expected a TSV with a column 's' (seconds)")
    rss = table["max_rss"] if "max_rss" in table.columns else pd.Series([float("nan")])
    return float(table["s"].sum()), float(pd.to_numeric(rss, errors="coerce").max())


def stage_timings(
    root: str | Path, subject: str, order: Iterable[str] = ()
) -> list[dict[str, object]]:
    """Wall-clock time per rule of one subject, from Snakemake benchmark files.

    Parameters
    ----------
    root : str or Path
        The benchmark folder, ``benchmarks/rules``; a missing folder gives no rows.
    subject : str
        Subject id: ``{root}/{rule}/{subject}.tsv`` and ``{root}/{rule}/{subject}/*.tsv`` count.
    order : iterable of str
        Rule names in the order the rows should follow (the workflow's); other rules follow
        alphabetically.

    Returns
    -------
    list of dict
        One per rule with benchmark files: ``stage`` (rule name), ``jobs`` (number of files),
        ``seconds`` (sum of their ``s``), ``max_rss_mb`` (largest resident set, MB; NaN if absent).

    Raises
    ------
    InputError
        A benchmark file without a column ``s``.
    """
    root = Path(root)
    if not root.is_dir():
        return []
    rows = []
    for rule_dir in sorted(p for p in root.iterdir() if p.is_dir()):
        files = [rule_dir / f"{subject}.tsv"] + sorted((rule_dir / subject).glob("*.tsv"))
        files = [f for f in files if f.is_file()]
        if not files:
            continue
        times = [_benchmark_seconds(f) for f in files]
        rows.append(
            {
                "stage": rule_dir.name,
                "jobs": len(files),
                "seconds": sum(t for t, _ in times),
                "max_rss_mb": float(pd.Series([r for _, r in times]).max()),
            }
        )
    rank = {name: i for i, name in enumerate(order)}
    rows.sort(key=lambda r: (rank.get(r["stage"], len(rank)), r["stage"]))
    return rows
