"""Check a config file before a run reads it: ``python tools/check_config.py my.yaml``.

Snakemake reads ``--configfile`` itself, before the workflow: a path that does not exist ends in
a 30-line traceback, a YAML syntax error in "Config file is not valid JSON or YAML" naming
neither the file nor the line. ``make run CONFIG=...`` runs this first, so that each is one line
naming the file and the line. A key (or a whole section) given twice, which Snakemake reads
silently keeping the last value, the workflow refuses itself when it loads, with the same line
(:func:`scan2morph.io.yaml_text.config_file_problem`, on every entry point); the config's keys
and values are checked by the run too (``schemas/config.schema.yaml``). Exit status 2 when the
file is refused.
"""

from __future__ import annotations

import sys

from scan2morph.io.yaml_text import config_file_problem


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        sys.stderr.write("usage: python tools/check_config.py CONFIG.yaml\n")
        return 2
    problem = config_file_problem(argv[0])
    if problem:
        sys.stderr.write(f"Error: {problem}\n")
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
