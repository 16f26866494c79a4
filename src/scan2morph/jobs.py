"""Running one pipeline job: logging to the job's log file, clear messages for bad input.

The workflow's adapter scripts call :func:`run_job`; it never imports snakemake.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import math
import os
import re
import secrets
import sys
import zipfile
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from scan2morph.errors import InputError, OutputError, disk_full, writing

log = logging.getLogger("scan2morph")


def run_job(log_path: str | Path | None, func: Callable[[], object]) -> None:
    """Run ``func`` with logging to ``log_path``.

    Everything (INFO and up, libraries included) goes to the job's log file; the console (stderr,
    which Snakemake shows beside its progress) gets only warnings and errors, one line each, so
    that a run's console shows its progress and its problems, not library chatter (PyOpenGL logs
    hundreds of INFO lines at shutdown). An :class:`~scan2morph.errors.InputError` is written to
    the log and to stderr as one clear line and the process exits with status 1 (no traceback:
    the message says what to fix). Any other exception is logged with its traceback and
    re-raised.
    """
    console = logging.StreamHandler(sys.stderr)
    console.setLevel(logging.WARNING)
    handlers: list[logging.Handler] = [console]
    if log_path:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(log_path, mode="w", encoding="utf-8"))
    logging.basicConfig(
        level=logging.INFO,
        format="%(asctime)s %(levelname)s %(message)s",
        handlers=handlers,
        force=True,
    )
    try:
        with opencv_threads(job_threads()):
            _profiled(func, log_path)
    except InputError as exc:
        log.error("%s", exc if isinstance(exc, OutputError) else f"bad input: {exc}")
        logging.shutdown()
        sys.exit(1)
    except Exception as exc:
        if disk_full(exc):  # any writer (HDF5, OBJ, glTF, JSON): one line, no traceback
            log.error(
                "no space left on device writing %s", getattr(exc, "filename", None) or "an output"
            )
            logging.shutdown()
            sys.exit(1)
        log.exception("job failed")
        logging.shutdown()
        raise


#: A job log's error line (:func:`run_job`'s format): its time stamp and its message.
_ERROR_LINE = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ ERROR (.*)$")


def job_error(logs: Iterable[str | Path], since: float) -> tuple[str, Path] | None:
    """The last error a job wrote in this run: the message of the last ``ERROR`` line of the
    first of ``logs`` written at or after ``since`` (seconds since the epoch) that has one
    (``bad input: `` left off), and that log; None when none has.

    For the run's last console lines: a subject its check or its own job stopped says why, not
    Snakemake's ``message: None``.
    """
    for path in map(Path, logs):
        if not path.is_file() or path.stat().st_mtime < since:
            continue
        errors = [m.group(1) for m in map(_ERROR_LINE.match, path.read_text().splitlines()) if m]
        if errors:
            message = errors[-1]
            return message.removeprefix("bad input: "), path
    return None


#: Environment variable naming a folder: every job then writes its cProfile statistics there
#: (``{log name}.prof``), its start-up (interpreter and imports) CPU time and its body's wall
#: and CPU time (``{log name}.json``), for ``benchmarks/bench_profile.py`` and
#: ``benchmarks/bench_subject_jobs.py``.
PROFILE_ENV = "SCAN2MORPH_PROFILE"


def job_threads() -> int | None:
    """The job's threads as Snakemake gives them (it sets ``OMP_NUM_THREADS`` to a job's
    ``threads``), or None outside a job."""
    n = os.environ.get("OMP_NUM_THREADS", "")
    return int(n) if n.isdigit() and int(n) > 0 else None


@contextmanager
def opencv_threads(n: int | None) -> Iterator[None]:
    """OpenCV's worker threads set to ``n`` for a while (None: left as they are).

    Snakemake limits a job's BLAS and OpenMP threads to its ``threads`` but not OpenCV's own
    pool, which takes every core: on a one-thread job its second thread made the refinement's
    optical flow cost a third more CPU for the same numbers (bit for bit: each thread works a
    stripe of the image). An OpenCV imported later reads ``OPENCV_FOR_THREADS_NUM``.
    """
    if n is None:
        yield
        return
    env = os.environ.get("OPENCV_FOR_THREADS_NUM")
    os.environ["OPENCV_FOR_THREADS_NUM"] = str(n)
    cv2 = sys.modules.get("cv2")
    before = cv2.getNumThreads() if cv2 is not None else None
    if cv2 is not None:
        cv2.setNumThreads(int(n))
    try:
        yield
    finally:
        if cv2 is not None:
            cv2.setNumThreads(before)
        if env is None:
            os.environ.pop("OPENCV_FOR_THREADS_NUM", None)
        else:
            os.environ["OPENCV_FOR_THREADS_NUM"] = env


#: Whether this process ran a profiled job body already (its start-up is counted once).
_STARTED = False


def _profiled(func: Callable[[], object], log_path: str | Path | None) -> None:
    """Run ``func``; profile it when :data:`PROFILE_ENV` names a folder."""
    folder = os.environ.get(PROFILE_ENV)
    if not folder or not log_path:
        func()
        return
    import cProfile
    import time

    global _STARTED
    parts = Path(log_path).with_suffix("").parts
    name = "-".join(parts[parts.index("logs") + 1 :] if "logs" in parts else parts[-2:])
    start = time.process_time()
    # the CPU so far: the interpreter, Snakemake's wrapper, imports; paid once a process (a
    # take's stages share one job: the later ones have none)
    startup = 0.0 if _STARTED else start
    _STARTED = True
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    try:
        profile.runcall(func)
    finally:
        wall = time.perf_counter() - t0
        cpu = time.process_time() - start
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        profile.dump_stats(out / f"{name}.prof")
        times = {"startup_cpu_s": startup, "body_wall_s": wall, "body_cpu_s": cpu}
        write_json(out / f"{name}.json", times)


#: Memory of reading a mesh scan and building its view, MB per MB of the file, binary (PLY, GLB)
#: and text (OBJ, glTF) formats: 1.5 times the measured (as every rule's request,
#: docs/cluster.md). Measured on the real head subdivided to 1.1 million triangles: PLY 23.8 MB,
#: 1.22 GB peak (about 33 MB per MB above a take job's 0.45 GB); OBJ 84.7 MB, the whole take job
#: 1.01 GB (about 6.5); a synthetic 108,000-triangle PLY of 2.3 MB: the whole take job 0.48 GB.
MESH_MB_PER_FILE_MB = {".ply": 50.0, ".glb": 50.0, ".obj": 10.0, ".gltf": 10.0}


def memory_mb(files: Iterable, base_mb: int) -> int:
    """A job's memory request: ``base_mb`` plus what reading the largest of its mesh scans takes.

    Parameters
    ----------
    files : iterable of path or of lists of paths
        The job's input files (a Snakemake job's ``input``); a file that does not exist yet (a
        synthetic take, made by the run) counts as empty.
    base_mb : int
        The job's memory without mesh scans, MB.

    Returns
    -------
    int
        MB (:data:`MESH_MB_PER_FILE_MB` times the largest mesh file's size, added).
    """
    largest = 0.0
    stack = list(files)
    while stack:
        item = stack.pop()
        if isinstance(item, (list, tuple)):
            stack.extend(item)
            continue
        path = Path(item)
        factor = MESH_MB_PER_FILE_MB.get(path.suffix.lower())
        if factor and path.is_file():
            largest = max(largest, factor * path.stat().st_size / 2**20)
    return int(base_mb + math.ceil(largest))


def sha256_file(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(chunk), b""):
            digest.update(block)
    return digest.hexdigest()


def write_npz(path: str | os.PathLike[str], arrays: Mapping[str, object]) -> None:
    """Write a compressed ``.npz`` with fixed zip timestamps, so equal arrays give equal bytes
    (``numpy.savez_compressed`` stamps each member with the time of writing).

    Deflate level 1: a take's truth (55k vertices) in 0.04 s instead of level 6's 0.13 s, 2%
    larger.

    Parameters
    ----------
    path : str or path-like
    arrays : mapping str -> array-like
        Written as ``{name}.npy`` members, in the mapping's order (no pickles).
    """
    import numpy as np  # here: most of this module's users need no numpy

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in arrays:
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            data = io.BytesIO()
            np.lib.format.write_array(data, np.asarray(arrays[name]), allow_pickle=False)
            zf.writestr(info, data.getvalue(), compresslevel=1)
    Path(path).write_bytes(buf.getvalue())


def files_sha256(files: Mapping[str, str | Path | Sequence[str | Path]]) -> dict[str, list[str]]:
    """:func:`sha256_file` of a take's input files, by sheet column (a column of several files,
    an RGB-D take's depth frames: one each, in order). A folder (one that holds no frame its
    reader takes, which the take's checks report) gets the SHA-256 of its files' names and
    checksums, in name order."""
    return {
        role: [_sha256_path(f) for f in ([paths] if isinstance(paths, (str, Path)) else paths)]
        for role, paths in files.items()
    }


def _sha256_path(path: str | Path) -> str:
    if not Path(path).is_dir():
        return sha256_file(path)
    return files_digest(f for f in sorted(Path(path).iterdir()) if f.is_file())


def files_digest(paths: Iterable[str | Path], head: str = "") -> str:
    """Hex SHA-256 of ``head`` and each file's name and :func:`sha256_file`, in order: one
    checksum for several files (a folder's, a mesh file's with the files it names)."""
    text = head + "".join(f"\n{Path(f).name}\0{sha256_file(f)}" for f in paths)
    return hashlib.sha256(text.encode()).hexdigest()


def config_sha256(config: Mapping, leave_out: Iterable[str] = ()) -> str:
    """SHA-256 of a configuration, independent of key order, without its top-level keys
    ``leave_out`` (those that do not reach what the hash stands for)."""
    drop = set(leave_out)
    kept = {k: v for k, v in config.items() if k not in drop}
    return hashlib.sha256(json.dumps(kept, sort_keys=True, default=str).encode()).hexdigest()


@contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """A temporary file beside ``path`` that replaces ``path`` when the block ends without error.

    Write to the yielded path; a failed block leaves ``path`` untouched and removes the
    temporary. The temporary is created (exclusively, under a random name) with mode 0o666, so
    the kernel applies the user's umask (and a directory's default ACL) exactly as for any
    ``open(path, "w")``: the result is 0644 under umask 022, 0640 under 027, never the private
    0600 of :func:`tempfile.mkstemp`. The umask itself is never read or changed (changing it is
    not thread-safe).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")
        try:
            os.close(os.open(tmp, flags, 0o666))
            break
        except FileExistsError:
            continue
    else:  # pragma: no cover - 100 collisions of 48 random bits
        raise FileExistsError(f"{path}: no free temporary name beside it")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_json(path: str | Path, data: dict) -> None:
    """Write a JSON file with sorted keys (stable diffs between runs)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with writing(path):
        Path(path).write_text(json.dumps(data, indent=2, sort_keys=True, default=_jsonable) + "\n")


def _jsonable(value):
    try:
        import numpy as np

        if isinstance(value, np.generic):
            return value.item()
        if isinstance(value, np.ndarray):
            return value.tolist()
    except ImportError:  # pragma: no cover
        pass
    raise TypeError(f"not JSON serialisable: {type(value)}")
