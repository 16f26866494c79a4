"""One tiny pipeline run shared by the report, cohort and sweep tests.

A single synthetic subject (neutral, two visemes, one expression) at 160 x 120 pixels and a
10-mode modal basis, run in a temporary working directory. The run is made once per test session
(the first test module that asks for it pays for it) and each module asks for the targets it needs;
Snakemake only runs what is missing. The config names a sweep table inside the working directory
that does not exist until a test writes it, so that writing it never changes the config (whose hash
is a parameter of the store rule).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from tests.support.workflow_api import REPO, run_workflow

SUBJECT = "synth01"
TAKES = [
    dict(take="neutral", kind="neutral", label="neutral"),
    dict(take="car", kind="viseme", label="car"),
    dict(take="too", kind="viseme", label="too"),
    dict(take="smile1", kind="expression", label="smile"),
]
SCANNER = dict(width=160, height=120, focal_px=362.5, distance_mm=1000.0)
HEADER = "subject\ttake\tkind\tlabel\tmodality\txyz\tcolor\tleft\tright\tcalibration\tlandmarks\n"


@dataclass(frozen=True)
class TinyRun:
    """A tiny run: its working directory and config files (repo config first)."""

    work: Path
    configfile: Path

    @property
    def configfiles(self) -> list[Path]:
        return [REPO / "config" / "config.yaml", self.configfile]

    @property
    def sweeps(self) -> Path:
        """The sweep table the config names (absent until a test writes it)."""
        return self.work / "sweeps.tsv"

    def path(self, *parts: str) -> Path:
        return self.work.joinpath(*parts)


_RUN: dict[str, TinyRun] = {}


def tiny_config(work: Path) -> Path:
    """Write an empty user sheet and the tiny config into ``work``; returns the config file.

    Its paths are relative to ``work`` (the run's working directory), so that the same config
    (and so each store's config hash) runs in any working directory (tests/workflow/test_slurm.py runs
    it again under SLURM)."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "subjects.tsv").write_text(HEADER)
    cfg = dict(
        subjects="subjects.tsv",
        synthetic=dict(subjects=1, takes=TAKES, scanner=SCANNER, stereo=dict(subjects=[])),
        modal=dict(modes=10, reconstruction_k=[1, 2, 5, 10]),
        sweeps="sweeps.tsv",
    )
    path = work / "tiny.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def tiny_run(tmp_path_factory, targets: list[str]) -> TinyRun:
    """The session's tiny run with ``targets`` (paths relative to its working directory) made."""
    if "run" not in _RUN:
        work = tmp_path_factory.mktemp("tiny_run")
        _RUN["run"] = TinyRun(work, tiny_config(work))
    run = _RUN["run"]
    ok = run_workflow(run.work, run.configfile, targets=targets, keep_going=False)
    assert ok, f"tiny run failed for {targets}; see {run.work / 'logs'}"
    return run
