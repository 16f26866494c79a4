"""Check a config file before a run reads it: ``python tools/check_config.py my.yaml``.

Snakemake reads ``--configfile`` itself: a path that does not exist ends in a 30-line traceback,
a YAML syntax error in "Config file is not valid JSON or YAML" naming neither the file nor the
line, and a key (or a whole section) given twice silently keeps its last value only. ``make
run CONFIG=...`` runs this first, so that each is one line naming the file and the line. The
config's keys and values are checked by the run itself (``schemas/config.schema.yaml``).
Exit status 2 when the file is refused.
"""

from __future__ import annotations

import sys
from pathlib import Path


def config_problem(path: str) -> str | None:
    """Why the config file ``path`` cannot be read (one line naming it), or None."""
    import yaml

    from scan2morph.io.yaml_text import load_yaml, yaml_problem

    file = Path(path)
    if not file.is_file():
        what = "is a folder" if file.is_dir() else "not found"
        return f"{path}: config file {what} (expected a YAML file, e.g. make run CONFIG=my.yaml)"
    try:
        doc = load_yaml(file.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError) as exc:
        return f"{path}: cannot read the config file: {exc}"
    except yaml.YAMLError as exc:
        return f"{path}: {yaml_problem(exc)}"
    if doc is not None and not isinstance(doc, dict):
        return f"{path}: expected a mapping of config sections, got {type(doc).__name__}"
    return None


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        sys.stderr.write("usage: python tools/check_config.py CONFIG.yaml\n")
        return 2
    problem = config_problem(argv[0])
    if problem:
        sys.stderr.write(f"Error: {problem}\n")
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
