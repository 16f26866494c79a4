"""A take's stages in one job: which of them to re-run, and each one's time on record.

One job per take runs the per-take stages (ingest, repair, landmarks, fit, align, refine) in one
process, so that the interpreter and the imports are paid once a take instead of once a stage.
A config change still re-runs only the stages it reaches: every stage's part is recorded with a
*fingerprint*, the SHA-256 of the stage's name, its ``Params`` and what it reads (the
fingerprints of the parts it reads, the checksums of the input files, the template's). A stage
whose part exists with the fingerprint it would have now is not run: its part is kept as it is,
byte for byte. The fingerprints of a take's parts are kept beside them in ``stages.json``
(:func:`read_fingerprints`, :func:`write_fingerprints`).

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
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

from scan2morph.jobs import write_json

#: The per-take stages in the order a take's job runs them.
STAGES = ("ingest", "repair", "landmarks", "fit", "align", "refine")

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


def read_fingerprints(path: str | Path) -> dict[str, str]:
    """The fingerprints recorded for a take's parts (stage -> fingerprint); ``{}`` when the file
    is missing or unreadable (every stage then runs)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}


def write_fingerprints(path: str | Path, fingerprints: Mapping[str, str]) -> None:
    """Record the fingerprints of a take's parts (stage -> fingerprint), replacing the file."""
    write_json(path, dict(fingerprints))


def up_to_date(
    recorded: Mapping[str, str], stage: str, print_: str, outputs: Iterable[str | Path]
) -> bool:
    """Whether a stage need not run: its recorded fingerprint is ``print_`` and every one of its
    ``outputs`` (its part and its other files) exists."""
    return recorded.get(stage) == print_ and all(Path(f).is_file() for f in outputs)


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


__all__ = [
    "BENCHMARK_COLUMNS",
    "STAGES",
    "benchmarked",
    "fingerprint",
    "read_fingerprints",
    "up_to_date",
    "write_benchmark",
    "write_fingerprints",
]
