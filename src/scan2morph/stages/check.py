"""Check: every problem of a subject's sheet rows and files at once, before any heavy job.

One job per subject reads each take's files with the ingest's own readers (:func:`run`) (no stereo matching,
rendering or resampling: :func:`scan2morph.io.check.take_file_problems`) and gathers them with
the sheet's problems (:func:`scan2morph.sheet.sheet_problems`), so that a scan in metres, a
landmark file with a wrong count and a missing colour image surface in one run, one line each.

A problem of the whole subject (a repeated take id, no neutral) or of its neutral stops the
subject; a problem of another take leaves that take out (its ingest records why,
:mod:`scan2morph.stages.failure`) and the subject is built from the rest.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from scan2morph.errors import InputError
from scan2morph.io.check import take_file_problems
from scan2morph.io.mesh_file import companion_files
from scan2morph.jobs import files_digest, files_sha256
from scan2morph.sheet import mm_per_unit
from scan2morph.stages.part import Part, Take
from scan2morph.template import Template

log = logging.getLogger("scan2morph")


@dataclass(frozen=True)
class Params:
    """The check has no parameters."""

    @classmethod
    def from_config(cls, config: Mapping) -> Params:
        """The (empty) parameters, whatever the config."""
        return cls()


def run(template: Template | None, take: Take, params: Params) -> Part:
    """Check one take's files with the ingest's own readers.

    Parameters
    ----------
    template : Template or None
        Not used (the contract's shape).
    take : Take
        Its ``row`` (``modality``) and ``files`` (the input files that exist, by sheet column).
    params : Params

    Returns
    -------
    Part
        No datasets; ``files["problems"]`` lists the take's problems, one line each.
    """
    problems = take_file_problems(take.row["modality"], take.files, mm_per_unit(take.row))
    return Part(files={"problems": problems})


def check_subject(subject: str, takes: Sequence[Take], sheet: Sequence[tuple[str, str]]) -> dict:
    """Check one subject: each take that the sheet did not refuse (:func:`run`), then the verdict.

    Parameters
    ----------
    subject : str
        The subject id.
    takes : sequence of Take
        The subject's takes in sheet order, each with its ``row`` (``take``, ``kind``,
        ``modality``) and ``files`` (the input files that exist).
    sheet : sequence of (take, problem)
        The sheet's problems (:func:`scan2morph.sheet.sheet_problems`); take empty for the
        subject's own.

    Returns
    -------
    dict
        ``subject``, ``problems`` (the subject's own: always empty on return) and ``takes``:
        take -> its problems (the takes to leave out), for ``results/{subject}/check.json``.

    Raises
    ------
    InputError
        A problem of the subject or of its neutral; every problem found is logged first, one
        line each.
    """
    own = [problem for take, problem in sheet if not take]
    found: dict[str, list[str]] = {}
    for take, problem in sheet:
        if take:
            found.setdefault(take, []).append(problem)
    params = Params()
    for take in takes:
        if take.take not in found:  # a row the sheet already refused is not read
            problems = run(None, take, params).files["problems"]
            if problems:
                found[take.take] = problems
    neutral = [t.take for t in takes if t.kind == "neutral"]
    for problem in own:
        log.warning("%s: %s", subject, problem)
    for take, problems in found.items():
        fate = "stops the subject" if take in neutral else "is left out"
        for problem in problems:
            log.warning("%s/%s %s: %s", subject, take, fate, problem)
    stopping = own + [p for t in neutral for p in found.get(t, [])]
    if stopping:
        n = len(own) + sum(map(len, found.values()))
        more = f" (and {len(stopping) - 1} more above)" if len(stopping) > 1 else ""
        raise InputError(  # the first problem that stops it quoted: the run's last lines say it
            f"subject {subject}",
            f"{n} problem{'s' * (n != 1)} (each above, one line); "
            + (
                "the subject's sheet rows are inconsistent"
                if own
                else f"its neutral take {neutral[0]} cannot be read, so the subject is not built"
            )
            + f": {stopping[0]}{more}",
        )
    return {"subject": subject, "problems": [], "takes": found}


def take_problem(check: Mapping, take: str) -> str:
    """The problems ``check.json`` found for one take, joined into one line ('' if none)."""
    return "; ".join(check.get("takes", {}).get(take, []))


def take_verdict(
    check: Mapping, take: Take, sheet: Sequence[str], checksums: Mapping[str, Sequence[str]]
) -> str:
    """A take's problems now, joined into one line ('' if none), for its own job.

    The subject's check job re-runs for a new sheet row or file and for its neutral's new
    content, not for another take's (those files are ``ancient`` inputs of it: a rewritten
    ``check.json`` would otherwise re-run every take of the subject). So its verdict counts only
    for the very files it read.

    Parameters
    ----------
    check : mapping
        ``check.json``: the verdicts and, under ``files``, the checksums of the files each
        take's verdict was found on.
    take : Take
        Its ``row`` and ``files`` (the input files that exist), for a check of its own.
    sheet : sequence of str
        The sheet's problems of the take (found when the workflow starts: always current).
    checksums : mapping sheet column -> list of str
        The SHA-256 of the take's files now (:func:`input_checksums`).

    Returns
    -------
    str
        The sheet's problems; else the check job's verdict when it read these files; else the
        take's files checked again (:func:`run`).
    """
    if sheet:
        return "; ".join(sheet)
    if check.get("files", {}).get(take.take) == {k: list(v) for k, v in checksums.items()}:
        return take_problem(check, take.take)
    return "; ".join(run(None, take, Params()).files["problems"])


def input_checksums(files: Mapping[str, object]) -> dict[str, list[str]]:
    """SHA-256 of a take's input files as their readers read them, by sheet column
    (:func:`scan2morph.jobs.files_sha256`): a mesh file's with the files it names folded in
    (:func:`scan2morph.io.mesh_file.companion_files`: an OBJ's MTL and texture, a glTF's
    buffers and images), so that a texture changed beside an unchanged OBJ changes the take.

    Parameters
    ----------
    files : mapping sheet column -> path or list of paths
        The take's input files that exist.

    Returns
    -------
    dict of str to list of str
        Hex digests; one per file, in order.
    """
    out = files_sha256(files)
    mesh = files.get("mesh")
    if others := companion_files(mesh) if isinstance(mesh, str) else []:
        out["mesh"] = [files_digest(others, head=out["mesh"][0])]
    return out


__all__ = ["Params", "check_subject", "input_checksums", "run", "take_problem", "take_verdict"]
