"""The tiny run submitted to SLURM, started when the test session starts (a pytest plugin that
tests/conftest.py loads; tests/workflow/test_slurm.py checks the result).

The plugin runs a group's rules one after another, each through ``srun`` and a Snakemake of its
own (~3 s of start-up and ~2 s of work a rule at 160 x 120 px), so the run takes ~4 minutes of
wall time on one core whatever the machine. Started at the beginning of the session, it runs
beside the rest of the suite, which leaves the second core idle most of the time, and
tests/workflow/test_slurm.py, which the conftest orders last, waits for it and checks it.

Needs ``slurm-wlm`` and ``munge`` (``make setup`` installs them) and the executor plugin
(requirements.lock); skips naming what is missing, except under CI (``CI`` set), where it fails.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.support.slurm_cluster import ClusterUnavailable, SlurmCluster

# tests/support/tiny_run.py imports Snakemake's API: only the fixtures that run the workflow import it, so
# that the conftest loading this plugin needs no more than the `test` extra
REPO = Path(__file__).resolve().parents[2]
TARGET = "results/synth01/synth01.h5"  # tests/support/tiny_run.py's SUBJECT
SNAKEMAKE = Path(sys.executable).with_name("snakemake")
# What the throw-away cluster lacks compared with a site: accounting (so job states come from
# squeue, which keeps finished jobs for MinJobAge=86400 s; no account is guessed either), and quick status checks: a
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
#: The longest the run may take, s (it takes ~4 minutes alone, up to ~6 beside the suite).
TIMEOUT_S = 1200


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


@dataclass
class SlurmRun:
    """The tiny run's store made under SLURM in ``work``: the running Snakemake until
    :meth:`wait` returns."""

    work: Path
    proc: subprocess.Popen

    @property
    def output(self) -> str:
        return (self.work / "snakemake.out").read_text()

    def wait(self, timeout: float = TIMEOUT_S) -> None:
        """Wait for Snakemake; fails with the end of its output unless it succeeded."""
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.stop()
            code = "timeout"
        cmd = " ".join(map(str, self.proc.args))
        assert code == 0, f"{cmd} failed ({code}):\n{self.output[-6000:]}"

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=60)


@pytest.fixture(scope="session")
def slurm_run(slurm_cluster, tmp_path_factory):
    """Start the tiny run under SLURM with ``profiles/slurm`` (in the background)."""
    from tests.support.tiny_run import SUBJECT, tiny_config

    assert TARGET == f"results/{SUBJECT}/{SUBJECT}.h5"
    work = tmp_path_factory.mktemp("slurm_run")
    config = tiny_config(work)  # paths relative to ``work``: the config hashes agree
    cmd = [
        str(SNAKEMAKE),
        "--workflow-profile",
        str(REPO / "profiles" / "slurm"),
        *CLUSTER_ARGS,
        "-s",
        str(REPO / "Snakefile"),
        "--configfile",
        str(REPO / "config" / "config.yaml"),
        str(config),
        "--",
        TARGET,
    ]
    env = {**slurm_cluster.env, "PYOPENGL_PLATFORM": "osmesa"}
    with open(work / "snakemake.out", "w") as out:  # the child keeps its own descriptor
        proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=out, stderr=subprocess.STDOUT)
    run = SlurmRun(work, proc)
    yield run
    run.stop()


def wants_slurm_run(item: pytest.Item) -> bool:
    return "slurm_run" in getattr(item, "fixturenames", ())


def pytest_collection_modifyitems(config, items):
    """The tests of the SLURM run go last, so that the run has the session to finish in."""
    items.sort(key=wants_slurm_run)  # stable: the others keep their order


@pytest.fixture(scope="session", autouse=True)
def _start_slurm_run(request):
    """Start the SLURM run before the first test when a selected test checks it. Whatever stops
    it from starting (a skip, a failure, any error) is left for that test to report: the
    fixture's outcome is cached, and the other tests must not inherit it."""
    if any(wants_slurm_run(item) for item in request.session.items):
        try:
            request.getfixturevalue("slurm_run")
        except (pytest.skip.Exception, pytest.fail.Exception, Exception):
            pass
