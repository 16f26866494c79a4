"""The repository's configuration and its schema as the tests read them.

Parsed once per test process with libyaml's parser (PyYAML's ``CSafeLoader``: the same
documents, about ten times faster than the pure-Python parser); each call returns its own deep
copy, so a test may edit what it gets.
"""

from __future__ import annotations

import copy
import functools
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
#: A 320 x 240 RGB-D sensor (the default optics at half the resolution; params of
#: :func:`scan2morph.synth.rgbd.make_rgbd_take`), for quick takes.
SMALL_RGBD = {
    "width": 320,
    "height": 240,
    "focal_px": 300.0,
    "color_width": 320,
    "color_height": 240,
    "color_focal_px": 310.0,
}


def load_yaml(path: str | Path) -> object:
    """A YAML file's document, parsed with libyaml's safe loader where PyYAML has it."""
    return yaml.load(Path(path).read_text(encoding="utf-8"), Loader=_LOADER)


@functools.cache
def _parsed(relative: str) -> object:
    return load_yaml(REPO / relative)


def repo_config() -> dict:
    """A fresh copy of ``config/config.yaml``."""
    return copy.deepcopy(_parsed("config/config.yaml"))


def config_schema() -> dict:
    """A fresh copy of ``schemas/config.schema.yaml``."""
    return copy.deepcopy(_parsed("schemas/config.schema.yaml"))
