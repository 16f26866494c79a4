"""The workflow through SLURM: a tiny cohort submitted with ``profiles/slurm`` to a single-node
cluster that the test starts itself (tests/slurm_cluster.py), against a local run of the same
config. Needs ``slurm-wlm`` and ``munge`` (``make setup`` installs them) and the executor plugin
(requirements.lock); skips naming what is missing, except under CI (``CI`` set), where it fails.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
import yaml

from scan2morph.model import load_model
from scan2morph.store.compare import store_differences
from tests.slurm_cluster import ClusterUnavailable, SlurmCluster
from tests.tiny_run import HEADER, SCANNER, TAKES
from tests.workflow_api import REPO

SUBJECTS = ["synth01", "synth02"]
# Three takes a subject, the fewest that run every stage: the neutral, one viseme (viseme motion,
# a one-component PCA and its blends) and one expression (its displacement, modal coordinates).
# Under SLURM each rule costs a Snakemake start-up (~7 CPU-s: parsing the workflow) on top of its
# ~3 CPU-s of work, so every take left out saves four rules (ingest, repair, fit, align) a subject:
# the test measured 664 CPU-s with 4 takes, 548-583 with 3 (README "Scaling out").
COHORT_TAKES = [t for t in TAKES if t["take"] in ("neutral", "car", "smile1")]
# Every array of the two stores agrees to 1e-12, or to 1e-9 of its largest value: two local runs
# do not agree to 1e-12 alone, because the alignment (open3d ICP) is not bit-reproducible (its
# transform moves by ~5e-13 mm from run to run), which the PCA eigenvalues (~1e5 mm^2) carry as
# ~2e-10 and the semantic modal modes (unit vectors) as up to 6.7e-12 on entries near zero: the
# noise scales with the array, not with each entry.
ATOL, RTOL = 1e-12, 1e-9
TARGETS = [f"results/{s}/{s}.h5" for s in SUBJECTS]
SNAKEMAKE = Path(sys.executable).with_name("snakemake")
# What the throw-away cluster lacks compared with a site: accounting (so job states come from
# squeue, kept for MinJobAge=3600 s; no account is guessed either), and quick status checks: a
# check is what lets a finished job's dependants be submitted. Snakemake waits
# --seconds-between-status-checks (default 10 s) before the first check; the plugin then adds
# 10 s after every check that finds no job finished (up to 180 s) and goes back to
# --slurm-init-seconds-before-status-checks (default 40 s) after one that does.
CLUSTER_ARGS = [
    "--slurm-status-command=squeue",
    "--seconds-between-status-checks=1",
    "--slurm-init-seconds-before-status-checks=1",
    "--slurm-keep-successful-logs",
]


def _unavailable(reason: str):
    if os.environ.get("CI"):
        pytest.fail(f"SLURM test cannot run under CI: {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="session")
def slurm_cluster(tmp_path_factory):
    """A running single-node SLURM cluster (munged, slurmctld, slurmd) for the session."""
    try:
        import snakemake_executor_plugin_slurm  # noqa: F401
    except ImportError:
        _unavailable("snakemake-executor-plugin-slurm is not installed (make setup)")
    if os.geteuid() != 0:
        _unavailable("the test cluster runs its daemons as root (SlurmUser=root)")
    cluster = SlurmCluster(tmp_path_factory.mktemp("slurm"))
    try:
        cluster.start()
    except ClusterUnavailable as err:
        _unavailable(f"the SLURM test cluster did not start: {err}")
    yield cluster
    cluster.stop()


def cohort_config(work: Path) -> Path:
    """tests/tiny_run.py's tiny config with two synthetic subjects of three takes; paths relative
    to ``work`` so that the config (and so each store's config hash) is the same in every working
    directory."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "subjects.tsv").write_text(HEADER)
    cfg = dict(
        subjects="subjects.tsv",
        synthetic=dict(subjects=2, takes=COHORT_TAKES, scanner=SCANNER, stereo=dict(subjects=[])),
        modal=dict(modes=10, reconstruction_k=[1, 2, 5, 10]),
        sweeps="sweeps.tsv",
    )
    path = work / "tiny.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def snakemake(work: Path, args: list[str], env: dict) -> subprocess.Popen:
    """Start ``snakemake <args>`` for the two stores in ``work`` (output in snakemake.out)."""
    config = cohort_config(work)
    cmd = [
        str(SNAKEMAKE),
        *args,
        "-s",
        str(REPO / "Snakefile"),
        "--configfile",
        str(REPO / "config" / "config.yaml"),
        str(config),
        "--",
        *TARGETS,
    ]
    with open(work / "snakemake.out", "w") as out:  # the child keeps its own descriptor
        return subprocess.Popen(cmd, cwd=work, env=env, stdout=out, stderr=subprocess.STDOUT)


def finish(proc: subprocess.Popen, work: Path, timeout: float) -> None:
    try:
        code = proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.terminate()
        proc.wait(timeout=60)
        code = "timeout"
    text = (work / "snakemake.out").read_text()
    assert code == 0, f"{' '.join(map(str, proc.args))} failed ({code}):\n{text[-6000:]}"


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
def test_tiny_cohort_through_slurm_equals_local_run(slurm_cluster, tmp_path):
    env = {**slurm_cluster.env, "PYOPENGL_PLATFORM": "osmesa"}
    local, slurm = tmp_path / "local", tmp_path / "slurm"
    # both at once: the local run fills the SLURM run's scheduling and polling pauses
    on_slurm = snakemake(
        slurm, ["--workflow-profile", str(REPO / "profiles" / "slurm"), *CLUSTER_ARGS], env
    )
    on_host = snakemake(local, ["--cores", "2"], env)
    try:
        finish(on_host, local, timeout=900)
        finish(on_slurm, slurm, timeout=900)
    finally:
        for proc in (on_host, on_slurm):
            if proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=60)

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

    for target in TARGETS:
        # the three takes ran every stage (a stage both runs skipped would compare equal)
        model = load_model(slurm / target)
        assert model.skipped == {}, (target, model.skipped)
        assert (set(model.visemes), set(model.coordinates)) == ({"car"}, {"smile1"}), target
        assert store_differences(local / target, slurm / target, ATOL, RTOL, "array") == []


def test_every_per_subject_rule_is_in_the_subject_group():
    """profiles/slurm runs a subject's rules as one group job; a per-subject rule left out of it
    makes Snakemake refuse the DAG (a rule outside the group between two inside it)."""
    import re

    import yaml

    groups = yaml.safe_load((REPO / "profiles" / "slurm" / "config.yaml").read_text())["groups"]
    grouped = {g.split("=")[0] for g in groups}
    text = "\n".join(p.read_text() for p in sorted((REPO / "workflow" / "rules").glob("*.smk")))
    blocks = re.split(r"^rule (\w+):", text, flags=re.M)[1:]
    per_subject = {
        name for name, body in zip(blocks[::2], blocks[1::2], strict=True) if "{subject}" in body
    }
    # jobs of their own: the sweeps (on demand) and the cohort summary over every subject
    own = {"sweep", "sweep_all", "cohort"}
    assert per_subject - own <= grouped, sorted(per_subject - own - grouped)
    assert {"refine", "align", "motion", "store"} <= per_subject
