"""Running the Snakemake workflow through snakemake's Python API (for the end-to-end tests)."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def snakemake_dry_run(workdir: Path, configfile: str) -> tuple[int, list[str]]:
    """The lines a user sees from ``snakemake -n`` in ``workdir`` with the repo's config and
    ``configfile`` on top (the CLI, as ``make dry-run`` runs it); also its exit status."""
    import subprocess
    import sys

    out = subprocess.run(
        [
            str(Path(sys.executable).parent / "snakemake"),
            "-s", str(REPO / "Snakefile"), "-n",
            "--configfile", str(REPO / "config" / "config.yaml"), configfile,
        ],
        cwd=workdir, capture_output=True, text=True,
    )  # fmt: skip
    return out.returncode, (out.stdout + out.stderr).strip().splitlines()


def run_workflow(
    workdir: Path, configfile: Path, targets=(), keep_going=True, cores=2, dryrun=False, repo=REPO
):
    """Run ``repo``'s Snakefile (this repository's by default) in ``workdir`` with its config
    and ``configfile`` over it; returns True on success."""
    # imported here: the unit tests import REPO from this module, and snakemake's API costs
    # every test worker about 0.8 s to import at collection
    from snakemake.api import SnakemakeApi
    from snakemake.settings.types import (
        ConfigSettings,
        DAGSettings,
        ExecutionSettings,
        OutputSettings,
        ResourceSettings,
    )

    with SnakemakeApi(OutputSettings(quiet=None, dryrun=dryrun, show_failed_logs=True)) as api:
        workflow = api.workflow(
            resource_settings=ResourceSettings(cores=cores),
            config_settings=ConfigSettings(
                configfiles=[Path(repo) / "config" / "config.yaml", configfile]
            ),
            snakefile=Path(repo) / "Snakefile",
            workdir=workdir,
        )
        dag = workflow.dag(dag_settings=DAGSettings(targets=set(targets)))
        try:
            dag.execute_workflow(
                executor="dryrun" if dryrun else "local",
                execution_settings=ExecutionSettings(keep_going=keep_going, latency_wait=1),
            )
        except Exception:  # snakemake raises when a job failed
            return False
    return True


def run_synthetic(workdir: Path, synthetic: dict, targets, **config) -> bool:
    """Run the workflow on a synthetic cohort alone: an empty subject sheet, the config's
    ``synthetic`` section as ``synthetic`` (over the repo's) and the other sections in
    ``config``, written to ``workdir/cfg.yaml``; True on success."""
    import yaml

    sheet = workdir / "subjects.tsv"
    sheet.write_text("subject\ttake\tkind\tlabel\tmodality\tlandmarks\n")
    cfg = dict(subjects=str(sheet), synthetic=synthetic, **config)
    (workdir / "cfg.yaml").write_text(yaml.safe_dump(cfg))
    return run_workflow(workdir, workdir / "cfg.yaml", targets=targets)
