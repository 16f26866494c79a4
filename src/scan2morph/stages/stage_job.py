"""Several stages in one job: which of them to re-run, and each one's time on record.

A take's stages (ingest, repair, landmarks, fit, align, refine: :data:`TAKE_STAGES`) run in one
job per take, and a subject's own stages after its takes (:data:`SUBJECT_STAGES`: its template
part, the takes' consensus, motion, click noise, morphable and modal models, store, head meshes, accuracy, figures and
report) in one job per subject, each in one process, so that the interpreter and the imports are
paid once a job instead of once a stage. A config change still re-runs only the stages it
reaches: every stage's outputs are recorded with a *fingerprint*, the SHA-256 of the stage's
name, its ``Params`` and what it reads (the fingerprints of the parts it reads, the checksums of
the input files, the template's, and its code's fingerprint: :func:`code_fingerprints` of the
library modules it runs, :data:`STAGE_CODE`). A stage whose outputs exist with the fingerprint
it would have now is not run: they are kept as they are, byte for byte. The fingerprints of a job's stages are
kept beside its parts in ``stages.json`` (:func:`read_fingerprints`, :func:`write_fingerprints`;
another job reads a part's with :func:`part_fingerprint`); :func:`run_stages` runs a job's
stages in order, each only when it is out of date.

Each stage that runs writes its own wall and CPU time to its own benchmark file, in Snakemake's
benchmark format (:func:`write_benchmark`), where the run-time tables read them.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import resource
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager, nullcontext
from pathlib import Path

from scan2morph.jobs import sha256_file, write_json

#: The per-take stages in the order a take's job runs them.
TAKE_STAGES = ("ingest", "repair", "landmarks", "fit", "align", "refine")

#: A subject's own stages after its takes, in the order its job runs them (a subject without
#: ground truth has no ``accuracy``).
SUBJECT_STAGES = (
    "template_part",
    "consensus",
    "motion",
    "motion_noise",
    "morph",
    "modal",
    "store",
    "head_meshes",
    "accuracy",
    "figures",
    "report_subject",
)

#: The library modules each stage runs (its stage module and what the workflow's job calls
#: for it); its code fingerprint covers these and every module they import
#: (:func:`scan2morph.provenance.code_fingerprint`), besides :data:`TAKE_CODE` or
#: :data:`SUBJECT_CODE`.
STAGE_CODE: dict[str, tuple[str, ...]] = {
    "ingest": ("scan2morph.stages.ingest",),
    "repair": ("scan2morph.stages.repair",),
    "landmarks": ("scan2morph.stages.landmarks", "scan2morph.io.landmarks"),
    "fit": ("scan2morph.stages.fit", "scan2morph.io.obj"),
    "align": ("scan2morph.stages.align",),
    "refine": ("scan2morph.stages.refine",),
    "template_part": ("scan2morph.stages.fit",),
    "consensus": ("scan2morph.stages.consensus",),
    "motion": ("scan2morph.stages.motion",),
    "motion_noise": ("scan2morph.stages.motion_noise", "scan2morph.tables"),
    "morph": ("scan2morph.stages.morph",),
    "modal": ("scan2morph.stages.modal",),
    "store": ("scan2morph.stages.store", "scan2morph.store.layout"),
    "head_meshes": ("scan2morph.morph.head",),
    "accuracy": ("scan2morph.stages.accuracy", "scan2morph.evaluate.truth"),
    "figures": ("scan2morph.render.figures",),
    "report_subject": ("scan2morph.stages.report", "scan2morph.report"),
}
#: The jobs outside a take's and a subject's, by name, and the library modules they run (with
#: every module those import, as :data:`STAGE_CODE`'s): the synthetic subjects' generator, the
#: template's builder, the cohort's summary. A change to their code runs them again.
JOB_CODE: dict[str, tuple[str, ...]] = {
    "synth": ("scan2morph.stages.synth",),
    "template": ("scan2morph.template",),
    "cohort": ("scan2morph.report",),
}
#: What every take stage's job runs besides the stage: parts, template, take isolation.
TAKE_CODE = ("scan2morph.store.hdf5", "scan2morph.template", "scan2morph.stages.failure")
#: What every subject stage's job runs besides the stage: parts, template, the job's log.
SUBJECT_CODE = ("scan2morph.store.hdf5", "scan2morph.template", "scan2morph.jobs")


#: Columns of Snakemake's benchmark files (``benchmark:`` of a rule), in its order.
BENCHMARK_COLUMNS = (
    "s",
    "h:m:s",
    "max_rss",
    "max_vms",
    "max_uss",
    "max_pss",
    "io_in",
    "io_out",
    "mean_load",
    "cpu_time",
)


def _plain(value: object) -> object:
    """``value`` as JSON-able data: dataclasses as dicts, tuples as lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # a numpy scalar
        return value.item()
    return value


def fingerprint(stage: str, params: object, reads: Mapping[str, object]) -> str:
    """The fingerprint of a stage's part: what it was computed from.

    Parameters
    ----------
    stage : str
        The stage's name.
    params : object
        The stage's ``Params`` (a dataclass; nested ones and tuples are taken apart) or any JSON-
        able data.
    reads : mapping str -> object
        What else the stage's result depends on, by name: the fingerprints of the parts it reads,
        the checksums of its input files, the take's ids (JSON-able).

    Returns
    -------
    str
        Hex SHA-256 (64 characters) of the canonical JSON of the three (keys sorted): equal
        inputs give equal fingerprints in any process.
    """
    text = json.dumps(
        {"stage": stage, "params": _plain(params), "reads": _plain(reads)},
        sort_keys=True,
        default=repr,
    )
    return hashlib.sha256(text.encode()).hexdigest()


def stage_code(stage: str) -> tuple[str, ...]:
    """The library modules a stage runs (:data:`STAGE_CODE` with its job's :data:`TAKE_CODE` or
    :data:`SUBJECT_CODE`); the store's are those of every stage that makes what it holds (the
    take stages and the subject's up to the store), so that its ``code_sha256`` names them; a
    job of :data:`JOB_CODE`'s, its modules."""
    if stage == "store":
        makers = [*TAKE_STAGES, *SUBJECT_STAGES[: SUBJECT_STAGES.index("store") + 1]]
        return tuple(sorted({m for s in makers if s != "store" for m in stage_code(s)}))
    if stage in JOB_CODE:
        return (*JOB_CODE[stage], "scan2morph.jobs")
    common = TAKE_CODE if stage in TAKE_STAGES else SUBJECT_CODE
    return (*STAGE_CODE[stage], *common)


def code_fingerprints(stages: Iterable[str], package_dir: Path | None = None) -> dict[str, str]:
    """Each stage's code fingerprint: what its result depends on besides its settings and
    inputs.

    Parameters
    ----------
    stages : iterable of str
        Stage names (:data:`STAGE_CODE`).
    package_dir : Path, optional
        The library's folder (default: this one's; tests give a copy).

    Returns
    -------
    dict of str to str
        Stage -> hex SHA-256 of the code of the modules it runs (:func:`stage_code`, with
        every module they import, their package data and the files outside the package they
        read, such as the report's viewer bundle: :func:`scan2morph.provenance.code_fingerprint`).
        A module's docstrings and comments do not count. The
        modules are parsed once (about 1 CPU-s for all of them; kept on disk after that,
        :func:`scan2morph.provenance.cache_file`): the workflow
        computes these once a run and hands them to the jobs (``params.code``), where
        :func:`fingerprint` takes them among a stage's reads.
    """
    from scan2morph.provenance import PACKAGE_DIR, code_fingerprint

    return {s: code_fingerprint(stage_code(s), package_dir or PACKAGE_DIR) for s in stages}


def read_fingerprints(path: str | Path) -> dict[str, str]:
    """The fingerprints recorded for a job's stages (stage -> fingerprint); ``{}`` when the file
    is missing or unreadable (every stage then runs)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}


def write_fingerprints(path: str | Path, fingerprints: Mapping[str, str]) -> None:
    """Record the fingerprints of a job's stages (stage -> fingerprint), replacing the file."""
    write_json(path, dict(fingerprints))


def up_to_date(
    recorded: Mapping[str, str], stage: str, print_: str, outputs: Iterable[str | Path]
) -> bool:
    """Whether a stage need not run: its recorded fingerprint is ``print_`` and every one of its
    ``outputs`` (its part and its other files and folders) exists."""
    return recorded.get(stage) == print_ and all(Path(f).exists() for f in outputs)


def part_fingerprint(part: str | Path) -> str:
    """The fingerprint of a part another job wrote: the one its job recorded for it (the
    ``stages.json`` beside it, under the part's stem: ``takes/{take}/fit.h5`` -> ``fit``), or
    the SHA-256 of its bytes where none is recorded.

    Parameters
    ----------
    part : str or Path
        The part's file.

    Returns
    -------
    str
        Hex SHA-256 (64 characters).
    """
    part = Path(part)
    recorded = read_fingerprints(part.parent / "stages.json").get(part.stem)
    return recorded or sha256_file(part)


def run_stages(
    stages: Iterable[str],
    plan: Callable[[str, Mapping[str, str]], tuple[str, Sequence[str | Path]]],
    run: Callable[[str], None],
    record: str | Path,
    summary: str | Path,
    benchmarks: Mapping[str, str | Path] | None = None,
    done: str | Path | None = None,
) -> dict[str, str]:
    """Run a job's stages in order, each only when it is out of date (:func:`up_to_date`).

    Parameters
    ----------
    stages : iterable of str
        The job's stages, each after the stages it reads.
    plan : callable
        ``plan(stage, prints)``: the stage's fingerprint (:func:`fingerprint`) and its outputs,
        given the fingerprints of the stages before it (``prints``, stage -> fingerprint).
    run : callable
        ``run(stage)`` writes the stage's outputs and its log.
    record : str or Path
        The job's ``stages.json``. A stage's fingerprint is taken out of it before the stage
        runs and put in once its outputs are written, so a stage cut short runs again.
    summary : str or Path
        The job's log: one line a stage, ``{stage}: run``, ``{stage}: up to date, not run`` or
        ``{stage}: failed`` (the job then stops: the stages after it are not run; the error is
        raised again).
    benchmarks : mapping str -> path, optional
        A stage's benchmark file (:func:`benchmarked`), written when it runs; a stage without
        one has none.
    done : str or Path, optional
        The job's record of a finished run, ``{"stages": {stage: fingerprint}}``, written once
        every stage is done: the same bytes whenever the stages are as before (the job's log
        says which ran), so that a job that re-ran with nothing to do re-runs nothing after
        it. The workflow declares it a plain output, so Snakemake deletes it when the job
        starts, and a job that fails leaves none: the next run runs the job again. (The stages'
        files are ``update()`` outputs, which Snakemake puts back when their job fails, with a
        new modification time: without this record the next run would take them for current
        and do nothing.)

    Returns
    -------
    dict of str to str
        Every stage's fingerprint.
    """
    recorded = read_fingerprints(record)
    prints: dict[str, str] = {}
    lines: list[str] = []
    for stage in stages:
        prints[stage], outputs = plan(stage, prints)
        if up_to_date(recorded, stage, prints[stage], outputs):
            lines.append(f"{stage}: up to date, not run")
        else:
            recorded.pop(stage, None)
            write_fingerprints(record, recorded)
            bench = (benchmarks or {}).get(stage)
            try:
                with benchmarked(bench) if bench else nullcontext():
                    run(stage)
            except BaseException:  # SystemExit too: a job's bad input (scan2morph.jobs.run_job)
                _write_lines(summary, [*lines, f"{stage}: failed"])
                raise
            recorded[stage] = prints[stage]
            write_fingerprints(record, recorded)
            lines.append(f"{stage}: run")
        _write_lines(summary, lines)
    if done is not None:  # the same bytes when nothing changed: what reads it is not re-run
        write_json(done, {"stages": prints})
    return prints


def _write_lines(path: str | Path, lines: Sequence[str]) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("".join(f"{line}\n" for line in lines))


def _reset_peak_rss() -> bool:
    """Reset this process's peak resident set (Linux ``clear_refs``); False where it cannot."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


def _peak_rss_mb() -> float:
    """This process's peak resident set (MB) since the last reset (``VmHWM``), or since it
    started (``getrusage``) where ``/proc`` does not say."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def write_benchmark(path: str | Path, wall_s: float, cpu_s: float, max_rss_mb: float) -> None:
    """Write one job's benchmark line in Snakemake's format (tab-separated, its columns).

    Parameters
    ----------
    path : str or Path
        The ``.tsv`` file (replaced).
    wall_s, cpu_s : float
        Wall-clock and CPU time (s).
    max_rss_mb : float
        Peak resident set size (MB).

    Notes
    -----
    Columns the process does not measure (``max_vms``, ``max_uss``, ``max_pss``, ``io_in``,
    ``io_out``) are ``NA``; ``mean_load`` is the CPU time over the wall time (%).
    """
    hms = str(datetime.timedelta(seconds=int(wall_s)))
    load = 100.0 * cpu_s / wall_s if wall_s > 0 else 0.0
    values = {
        "s": f"{wall_s:.4f}",
        "h:m:s": hms,
        "max_rss": f"{max_rss_mb:.2f}",
        "mean_load": f"{load:.2f}",
        "cpu_time": f"{cpu_s:.4f}",
    }
    row = [values.get(c, "NA") for c in BENCHMARK_COLUMNS]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("\t".join(BENCHMARK_COLUMNS) + "\n" + "\t".join(row) + "\n")


@contextmanager
def benchmarked(path: str | Path) -> Iterator[None]:
    """Time the block (wall, CPU and peak memory of this process) into a benchmark file
    (:func:`write_benchmark`), written when the block ends, with or without an error."""
    _reset_peak_rss()
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        yield
    finally:
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        write_benchmark(path, wall, cpu, _peak_rss_mb())


def check_stage_params(config: Mapping) -> None:
    """Build every stage's ``Params`` from a (schema-checked) ``config`` once, so that what a
    schema cannot check, one setting against another (``refine.jaw.start`` below ``end``,
    ``fade_rmse_ratio`` not below ``max_rmse_ratio``, a membrane's mimic mass on a shell),
    stops a run at its start: in a take's job it would leave every take out alike, each with
    the same line, and in a subject's job stop every subject. The take stages and the subject
    stages with a module of their own (the others, the figures, the report and the head
    meshes, are drawn from what those write).

    Raises
    ------
    InputError
        The parameters' own one line (``config: refine.jaw: ...``).
    """
    import importlib
    import importlib.util

    for stage in (*TAKE_STAGES, *SUBJECT_STAGES):
        name = f"scan2morph.stages.{stage}"
        if importlib.util.find_spec(name) is not None:
            importlib.import_module(name).Params.from_config(config)


__all__ = [
    "BENCHMARK_COLUMNS",
    "JOB_CODE",
    "SUBJECT_STAGES",
    "TAKE_STAGES",
    "benchmarked",
    "STAGE_CODE",
    "check_stage_params",
    "code_fingerprints",
    "fingerprint",
    "part_fingerprint",
    "read_fingerprints",
    "run_stages",
    "stage_code",
    "up_to_date",
    "write_benchmark",
    "write_fingerprints",
]
