"""Machine-checking a store against the layout in ``schemas/store.layout.yaml``.

The layout lists every dataset by a path pattern (``/takes/{take}/mesh/vertices``), a dtype kind
and a shape made of integers and symbols (``[V, 3]``). A symbol must take one value everywhere in
the file, except the ones the layout declares ``local`` (bound afresh for each instance of the
path's placeholders, e.g. a take's image size H x W). A ``required`` dataset must exist for every
instance of its placeholders, where the instances are the group names found at the placeholder's
position (every take under ``/takes``).
"""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import yaml

from scan2morph.store.hdf5 import hdf5_output

_KINDS = {
    "float": "f",
    "int": "iu",
    "uint8": "u",
    "bool": "b",
    "str": "OSU",
}


def load_layout(path: str | Path) -> dict:
    """Read the layout YAML."""
    with open(path, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def _pattern_regex(pattern: str) -> re.Pattern:
    parts = re.split(r"(\{[a-z_]+\})", pattern)
    rx = "".join(f"(?P<{p[1:-1]}>[^/]+)" if p.startswith("{") else re.escape(p) for p in parts)
    return re.compile(f"^{rx}$")


def _instances(h5: h5py.File, pattern: str) -> list[dict]:
    """Every binding of the pattern's placeholders to group names present in the file."""
    head, sep, _ = pattern.partition("{")
    if not sep:
        return [{}]
    name = pattern[len(head) + 1 : pattern.index("}")]
    parent = head.rstrip("/") or "/"
    if parent not in h5 or not isinstance(h5[parent], h5py.Group):
        return []
    return [{name: key} for key in h5[parent].keys() if isinstance(h5[parent][key], h5py.Group)]


def validate_store(path: str | Path, layout: dict) -> list[str]:
    """Check a store against a layout.

    Returns
    -------
    problems : list of str
        Empty when the file conforms; otherwise one line per problem, naming the dataset.
    """
    problems: list[str] = []
    local = set(layout.get("local_symbols", []))
    bound: dict[str, int] = {}
    with h5py.File(path, "r") as h5:
        for attr in layout.get("root_attributes", []):
            if attr not in h5.attrs:
                problems.append(f"/: root attribute '{attr}' missing")
        found: list[str] = []
        h5.visititems(lambda n, o: found.append("/" + n) if isinstance(o, h5py.Dataset) else None)
        for entry in layout["datasets"]:
            pattern = entry["path"]
            rx = _pattern_regex(pattern)
            matches = {p: rx.match(p).groupdict() for p in found if rx.match(p)}
            if entry.get("required", False):
                have = {tuple(sorted(b.items())) for b in matches.values()}
                for inst in _instances(h5, pattern):
                    if tuple(sorted(inst.items())) not in have:
                        problems.append(f"{pattern.format(**inst)}: required dataset missing")
            for ds_path, binding in sorted(matches.items()):
                ds = h5[ds_path]
                kinds = _KINDS[entry["dtype"]]
                if ds.dtype.kind not in kinds or (
                    entry["dtype"] == "uint8" and ds.dtype.itemsize != 1
                ):
                    problems.append(f"{ds_path}: dtype {ds.dtype}, expected {entry['dtype']}")
                shape = entry.get("shape")
                if shape is None:
                    continue
                if len(shape) != ds.ndim:
                    problems.append(f"{ds_path}: shape {ds.shape}, expected {shape}")
                    continue
                scope = dict(bound)
                for want, got in zip(shape, ds.shape, strict=True):
                    if isinstance(want, int):
                        if want != got:
                            problems.append(f"{ds_path}: shape {ds.shape}, expected {shape}")
                            break
                        continue
                    key = want if want not in local else f"{want}@{sorted(binding.items())}"
                    table = bound if want not in local else scope
                    if key in table and table[key] != got:
                        problems.append(
                            f"{ds_path}: dimension {want} is {got} here but {table[key]} elsewhere"
                        )
                        break
                    table[key] = got
                    bound.update({k: v for k, v in scope.items() if "@" in k})
    return problems


def describe_store(path: str | Path, layout: dict) -> int:
    """Give every dataset of a store the ``units`` and ``description`` attributes of its layout
    entry, so that the file explains itself in any HDF5 viewer (HDFView, h5dump, h5py).

    Returns
    -------
    int
        The number of datasets described.
    """
    with hdf5_output(path, "a") as h5:
        return describe(h5, layout)


def describe(h5: h5py.File, layout: dict) -> int:
    """:func:`describe_store` on an open (e.g. in-memory) file."""
    entries = [(_pattern_regex(e["path"]), e) for e in layout["datasets"]]
    found: list[str] = []
    h5.visititems(lambda n, o: found.append("/" + n) if isinstance(o, h5py.Dataset) else None)
    for name in found:
        entry = next((e for rx, e in entries if rx.match(name)), None)
        if entry is None:
            continue
        h5[name].attrs["units"] = str(entry.get("units", ""))
        h5[name].attrs["description"] = " ".join(str(entry.get("description", "")).split())
    return len(found)
