"""The versioned per-subject HDF5 store."""

from scan2morph.store import paths
from scan2morph.store.hdf5 import (
    FORMAT_VERSION,
    merge_parts,
    open_store,
    read_attrs,
    read_group_attrs,
    read_part,
    read_parts,
    write_part,
)
from scan2morph.store.layout import describe_store, load_layout, validate_store

__all__ = [
    "FORMAT_VERSION",
    "describe_store",
    "load_layout",
    "merge_parts",
    "open_store",
    "paths",
    "read_attrs",
    "read_group_attrs",
    "read_part",
    "read_parts",
    "validate_store",
    "write_part",
]
