"""The workflow through SLURM: the tiny run (tests/support/tiny_run.py) submitted with ``profiles/slurm``
to a single-node cluster that the test session starts itself (tests/support/slurm_cluster.py), against
the session's local tiny run of the same config. The run starts with the session and runs beside
the other tests (tests/support/slurm_run.py); the test that checks it runs last.
"""

from __future__ import annotations

import re
import subprocess
from collections import Counter
from pathlib import Path

import pytest
import yaml

from scan2morph.model import load_model
from scan2morph.store.compare import store_differences
from tests.support.slurm_run import TARGET
from tests.support.tiny_run import TAKES, tiny_run
from tests.support.workflow_api import REPO

# The session's tiny run (tests/support/tiny_run.py: one synthetic subject, the neutral, two visemes and an
# expression, so every stage runs) is the local run the SLURM run must equal: the other workflow
# tests make it anyway.
# Every array of the two stores agrees to 1e-12, or to 1e-9 of its largest value: two local runs
# do not agree to 1e-12 alone, because the alignment (open3d ICP) is not bit-reproducible (its
# transform moves by ~5e-13 mm from run to run), which the PCA eigenvalues (~1e5 mm^2) carry as
# ~2e-10 and the semantic modal modes (unit vectors) as up to 6.7e-12 on entries near zero: the
# noise scales with the array, not with each entry.
ATOL, RTOL = 1e-12, 1e-9


def slurm_jobs(work: Path) -> dict[str, list[str]]:
    """The rules that ran inside each SLURM job, by SLURM job id, from the executor plugin's
    per-job logs (.snakemake/slurm_logs/{rule,group}_<name>/.../<jobid>.log: the output of the
    Snakemake that ran the job in the allocation, and of the one it started with srun for each
    rule, which runs it as a ``localrule``)."""
    return {
        log.stem: re.findall(r"^localrule (\w+):", log.read_text(), re.M)
        for log in (work / ".snakemake" / "slurm_logs").rglob("*.log")
    }


def planned_jobs(work: Path) -> Counter:
    """The jobs of a run by rule, from the "Job stats" table in Snakemake's output."""
    text = (work / "snakemake.out").read_text()
    table = text.split("Job stats:", 1)[1].split("total", 1)[0]
    return Counter({m[0]: int(m[1]) for m in re.findall(r"^(\w+)\s+(\d+)$", table, re.M)})


@pytest.mark.slow
def test_tiny_run_through_slurm_equals_local_run(slurm_cluster, slurm_run, tmp_path_factory):
    local = tiny_run(tmp_path_factory, [TARGET])
    slurm_run.wait()
    slurm = slurm_run.work

    # every job ran inside a SLURM job: each job of the run finished in one of the logs the
    # plugin names by SLURM job id, and squeue (MinJobAge keeps finished jobs) has each of
    # those jobs as COMPLETED
    jobs = slurm_jobs(slurm)
    ran = Counter(rule for rules in jobs.values() for rule in rules)
    assert ran == planned_jobs(slurm), (ran, planned_jobs(slurm))
    states = subprocess.run(
        ["squeue", "-h", "-t", "all", "-o", "%i %T"],
        capture_output=True,
        text=True,
        env=slurm_cluster.env,
        check=True,
    ).stdout
    state = dict(line.split() for line in states.splitlines())
    assert all(state.get(i) == "COMPLETED" for i in jobs), (states, jobs)

    # the takes ran every stage (a stage both runs skipped would compare equal)
    model = load_model(slurm / TARGET)
    assert model.skipped == {}, model.skipped
    by_kind = {k: {t["take"] for t in TAKES if t["kind"] == k} for k in ("viseme", "expression")}
    assert (set(model.visemes), set(model.coordinates)) == (
        by_kind["viseme"],
        by_kind["expression"],
    )
    assert store_differences(local.path(TARGET), slurm / TARGET, ATOL, RTOL, "array") == []


def test_every_per_subject_rule_is_in_the_subject_group():
    """profiles/slurm runs a subject's rules as one group job; a per-subject rule left out of it
    makes Snakemake refuse the DAG (a rule outside the group between two inside it)."""
    groups = yaml.safe_load((REPO / "profiles" / "slurm" / "config.yaml").read_text())["groups"]
    grouped = {g.split("=")[0] for g in groups}
    text = "\n".join(p.read_text() for p in sorted((REPO / "workflow" / "rules").glob("*.smk")))
    blocks = re.split(r"^rule (\w+):", text, flags=re.M)[1:]
    per_subject = {
        name for name, body in zip(blocks[::2], blocks[1::2], strict=True) if "{subject}" in body
    }
    # a rule made from another (`use rule subject as subject_synthetic`) is one like it
    derived = re.findall(r"^use rule (\w+) as (\w+)", text, flags=re.M)
    per_subject |= {name for base, name in derived if base in per_subject}
    # jobs of their own: the sweeps (on demand) and the cohort summary over every subject
    own = {"sweep", "sweep_all", "cohort"}
    assert per_subject - own <= grouped, sorted(per_subject - own - grouped)
    assert {"take", "subject", "subject_synthetic"} <= per_subject
