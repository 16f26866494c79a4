"""Are two stores (or parts) the same? Dataset by dataset, to a tolerance.

For reproducibility checks: the same inputs and config must give the same numbers, whether run
before or after a refactoring, locally or on a cluster.

Attributes are compared too, except the root's provenance (:data:`RUN_ATTRIBUTES`) and wall
times (keys named in :data:`TIMING_KEYS`, also inside JSON-valued attributes such as a stereo
take's reconstruction report).

Command line: ``python -m scan2morph.store.compare A.h5 B.h5 [--atol 1e-12]`` prints one line per
difference and exits 1 when there is any.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable
from pathlib import Path

import h5py
import numpy as np

from scan2morph.store.hdf5 import attr_value, read_part

#: Root attributes that describe the run rather than its numbers.
RUN_ATTRIBUTES = (
    "scan2morph_version",
    "config_sha256",
    "code_sha256",
    "dependencies",
    "git_commit",
    "git_dirty",
)
#: Attribute keys holding wall-clock times (they differ between any two runs).
TIMING_KEYS = ("timings_s",)


def store_differences(
    a: str | Path, b: str | Path, atol: float = 1e-12, rtol: float = 0.0, scale: str = "element"
) -> list[str]:
    """Every difference between the datasets of two HDF5 stores or parts.

    Parameters
    ----------
    a, b : str or Path
        The two files.
    atol, rtol : float
        Tolerances of numeric datasets (``|a - b| <= atol + rtol * |b|``, NaN equal to NaN);
        text and boolean datasets must be equal.
    scale : {"element", "array"}
        What ``rtol`` is relative to: each element's ``|b|``, or the dataset's largest
        ``|b|`` (for last-bit noise that scales with the array, not with each element: a unit
        mode vector's near-zero entries move as much as its large ones).

    Returns
    -------
    list of str
        One line per dataset that is missing on one side, differs in shape or dtype kind, or
        differs in value (with the largest absolute difference), and one per attribute that
        differs; empty when they agree.
    """
    if scale not in ("element", "array"):
        raise ValueError(f"scale: expected 'element' or 'array', got {scale!r}")
    da, db = read_part(a), read_part(b)
    out = _one_sided(da, db, a, b)
    for key in sorted(set(da) & set(db)):
        out += _differences(key, np.asarray(da[key]), np.asarray(db[key]), atol, rtol, scale)
    aa, ab = _attributes(a), _attributes(b)
    out += _one_sided(aa, ab, a, b)
    for key in sorted(set(aa) & set(ab)):
        x, y = aa[key], ab[key]
        if isinstance(x, str) or isinstance(y, str):
            if x != y:
                out.append(f"{key}: {x!r} != {y!r}")
        else:
            out += _differences(key, np.asarray(x), np.asarray(y), atol, rtol, scale)
    return out


def _one_sided(da: dict, db: dict, a, b) -> list[str]:
    return [f"{k}: only in {a}" for k in sorted(set(da) - set(db))] + [
        f"{k}: only in {b}" for k in sorted(set(db) - set(da))
    ]


def _attributes(path: str | Path) -> dict[str, object]:
    """Every attribute as ``{object path}@{key}`` (JSON values flattened one level), without the
    run's provenance and wall times."""
    out: dict[str, object] = {}

    def add(name: str, obj) -> None:
        for key, value in obj.attrs.items():
            if key in TIMING_KEYS or (name == "/" and key in RUN_ATTRIBUTES):
                continue
            value = value.decode() if isinstance(value, bytes) else value
            parsed = attr_value(value)
            if isinstance(parsed, dict):
                for k, v in parsed.items():
                    if k not in TIMING_KEYS:
                        out[f"{name}@{key}.{k}"] = json.dumps(v, sort_keys=True)
            else:
                out[f"{name}@{key}"] = value

    with h5py.File(path, "r") as h5:
        add("/", h5)
        h5.visititems(lambda name, obj: add(f"/{name}", obj))
    return out


def _differences(
    key: str, x: np.ndarray, y: np.ndarray, atol: float, rtol: float, scale: str
) -> list[str]:
    if x.shape != y.shape:
        return [f"{key}: shape {x.shape} != {y.shape}"]
    numeric = {x.dtype.kind, y.dtype.kind} <= set("iuf")
    if not numeric:
        if x.dtype.kind != y.dtype.kind or not np.array_equal(x, y):
            return [f"{key}: values differ ({x.dtype} vs {y.dtype})"]
        return []
    x, y = x.astype(np.float64), y.astype(np.float64)
    if not np.array_equal(np.isnan(x), np.isnan(y)):
        return [f"{key}: NaN in different places"]
    both = ~np.isnan(x)
    diff = np.abs(x[both] - y[both])
    size = np.abs(y[both])
    if scale == "array" and size.size:
        size = size.max()
    if diff.size and (diff > atol + rtol * size).any():
        return [f"{key}: max |difference| {diff.max():.3g}"]
    return []


def main(argv: Iterable[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("a")
    parser.add_argument("b")
    parser.add_argument("--atol", type=float, default=1e-12)
    parser.add_argument("--rtol", type=float, default=0.0)
    parser.add_argument("--scale", choices=("element", "array"), default="element")
    args = parser.parse_args(None if argv is None else list(argv))
    lines = store_differences(args.a, args.b, args.atol, args.rtol, args.scale)
    for line in lines:
        print(line)
    return 1 if lines else 0


if __name__ == "__main__":
    sys.exit(main())
