"""Check: every problem of a subject's sheet rows and files at once, before any heavy job.

One job per subject reads each take's files with the ingest's own readers (no stereo matching,
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

from scan2morph.errors import InputError
from scan2morph.io.check import take_file_problems

log = logging.getLogger("scan2morph")


def run(
    subject: str,
    rows: Sequence[Mapping[str, str]],
    files: Mapping[str, Mapping[str, str]],
    sheet: Sequence[tuple[str, str]],
) -> dict:
    """Check one subject.

    Parameters
    ----------
    subject : str
        The subject id.
    rows : sequence of mapping
        The subject's sheet rows (``take``, ``kind``, ``modality``), in sheet order.
    files : mapping take -> (mapping sheet column -> path)
        Each take's input files that exist.
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
    takes: dict[str, list[str]] = {}
    for take, problem in sheet:
        if take:
            takes.setdefault(take, []).append(problem)
    for row in rows:
        take = row["take"]
        if take not in takes:  # a row the sheet already refused is not read
            found = take_file_problems(row["modality"], files.get(take, {}))
            if found:
                takes[take] = found
    neutral = [r["take"] for r in rows if r["kind"] == "neutral"]
    for problem in own:
        log.warning("%s: %s", subject, problem)
    for take, problems in takes.items():
        fate = "stops the subject" if take in neutral else "is left out"
        for problem in problems:
            log.warning("%s/%s %s: %s", subject, take, fate, problem)
    stopping = own + [p for t in neutral for p in takes.get(t, [])]
    if stopping:
        n = len(own) + sum(map(len, takes.values()))
        raise InputError(
            f"subject {subject}",
            f"{n} problem{'s' * (n != 1)} (each above, one line); "
            + (
                "the subject's sheet rows are inconsistent"
                if own
                else f"its neutral take {neutral[0]} cannot be read, so the subject is not built"
            ),
        )
    return {"subject": subject, "problems": [], "takes": takes}


def take_problem(check: Mapping, take: str) -> str:
    """The problems ``check.json`` found for one take, joined into one line ('' if none)."""
    return "; ".join(check.get("takes", {}).get(take, []))


__all__ = ["run", "take_problem"]
