"""Run one take's stages in one process: ingest, repair, landmarks, fit, align, refine.

A stage whose part is up to date (its fingerprint, :mod:`scan2morph.stages.stage_job`) is not
run; one that runs writes its part, its other files, its log and its benchmark as its own job
did, with take isolation (:func:`scan2morph.stages.failure.run_take_job`).
"""

import functools
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from scan2morph.errors import InputError
from scan2morph.io import write_landmarks3d, write_obj, write_pts
from scan2morph.io.landmarks import LEFT_OUT
from scan2morph.io.obj import write_failed_obj
from scan2morph.jobs import sha256_file, write_json
from scan2morph.sheet import PATH_SEPARATOR, ROW_LOCATION, mm_per_unit
from scan2morph.stages import Take, align, check, fit, ingest, landmarks, refine, repair
from scan2morph.stages.failure import run_take_job
from scan2morph.stages.stage_job import TAKE_STAGES, fingerprint, read_fingerprints, run_stages
from scan2morph.store import paths, read_attrs, read_part, read_parts, write_part
from scan2morph.template import load_template

MODULES = {
    "ingest": ingest,
    "repair": repair,
    "landmarks": landmarks,
    "fit": fit,
    "align": align,
    "refine": refine,
}


def _value(files):
    """One input's file, or several (an RGB-D take's depth frames) joined as in the sheet."""
    return files if isinstance(files, str) else PATH_SEPARATOR.join(files)


def _take(j, data, attrs=None):
    return Take(j.w.subject, j.w.take, **j.p.take, data=data, attrs=attrs or {})


def run_ingest(j):
    """Read the take's files onto its pixel grid (the subject's check may have refused it)."""
    if j.problem:  # found by the subject's check job: the take is left out
        raise InputError(f"{j.w.subject}/{j.w.take}", j.problem)
    files = {role: _value(j.inp[role]) for role in j.p.roles}
    take = Take.from_row(j.p.row, files=files)
    part = ingest.run(None, take, j.params("ingest"))
    write_part(j.out.ingest, part.datasets, attrs=part.attrs)


def run_repair(j):
    """Repair the range image: its part and its report."""
    attrs = read_attrs(j.out.ingest, paths.take(j.w.take))
    take = _take(j, read_part(j.out.ingest), attrs)
    part = repair.run(None, take, j.params("repair"))
    write_part(j.out.repair, part.datasets, attrs=part.attrs)
    write_json(j.out.repair_report, part.files["report"])


def run_landmarks(j):
    """Settle the 68 landmarks (the neutral's carried over): its part, the .pts file and the
    points on the surface (.xyz: a mesh take's in the mesh's units, as its landmark file takes
    them; mm otherwise)."""
    take = _take(j, read_parts(j.reads["landmarks"]))
    part = landmarks.run(j.template(), take, j.params("landmarks"))
    write_part(j.out.landmarks, part.datasets, attrs=part.attrs)
    write_pts(j.out.pts, part.files["pts"])
    write_landmarks3d(j.out.xyz, part.files["xyz"] / landmarks_unit(j))


def run_fit(j):
    """Fit the template: its part and the OBJ, MTL and PNG."""
    attrs = read_attrs(j.out.repair, paths.take(j.w.take))
    take = _take(j, read_parts(j.reads["fit"]), attrs)
    part = fit.run(j.template(), take, j.params("fit"))
    write_part(j.out.fit, part.datasets, attrs=part.attrs)
    mesh = {k: part.datasets[paths.mesh(j.w.take, k)] for k in ("vertices", "uv", "valid")}
    write_obj(j.out.obj, faces=part.files["faces"], texture=part.files["texture"], **mesh)


def run_align(j):
    """Align the fitted mesh to the neutral's."""
    take = _take(j, read_parts(j.reads["align"]))
    part = align.run(j.template(), take, j.params("align"))
    write_part(j.out.align, part.datasets, attrs=part.attrs or None)


def run_refine(j):
    """Refine the correspondence to the neutral."""
    take = _take(j, read_parts(j.reads["refine"]))
    part = refine.run(j.template(), take, j.params("refine"))
    write_part(j.out.refine, part.datasets, attrs=part.attrs or None)


RUN = {
    "ingest": run_ingest,
    "repair": run_repair,
    "landmarks": run_landmarks,
    "fit": run_fit,
    "align": run_align,
    "refine": run_refine,
}


def on_failure(j, stage):
    """Writes a failed take's other outputs of ``stage`` (None: it has none)."""
    out = j.out
    return {
        "repair": lambda record, _: write_json(out.repair_report, {"failed": str(record)}),
        "landmarks": lambda record, error: write_left_out_landmarks(j, record, error),
        "fit": lambda record, _: write_failed_obj(out.obj, str(record)),
    }.get(stage)


def write_left_out_landmarks(j, record, error):
    """A take left out at its landmarks: its refused detection, to correct and give back, with
    a first line saying why; else (no points: no face found, a record handed on) the record
    alone (:data:`~scan2morph.io.landmarks.LEFT_OUT`)."""
    points, surface = getattr(error, "points", None), getattr(error, "surface", None)
    has_points = _finite(points)
    note = f"detected landmarks refused ({record}): correct them and give this file back"
    if has_points:
        write_pts(j.out.pts, points, comment=note)
    else:
        Path(j.out.pts).write_text(f"{LEFT_OUT}{record}\n")
    if has_points and _finite(surface):  # no comment: MeshLab opens it
        write_landmarks3d(j.out.xyz, surface / landmarks_unit(j))
    else:
        Path(j.out.xyz).write_text(f"{LEFT_OUT}{record}\n")


def _finite(values) -> bool:
    return values is not None and bool(np.isfinite(values).all())


def landmarks_unit(j) -> float:
    """mm per unit of the take's ``.xyz`` landmark file: a mesh take's in its mesh's units (as
    its landmarks column takes them), mm otherwise."""
    return mm_per_unit(j.p.row) if j.p.row.get("modality") == "mesh" else 1.0


def outputs(j, stage):
    """Every file ``stage`` writes for the take."""
    out = j.out
    extra = {
        "repair": [out.repair_report],
        "landmarks": [out.pts, out.xyz],
        "fit": [out.obj, out.mtl, out.texture],
    }
    return [out[stage], *extra.get(stage, [])]


#: The parts each stage reads: the take's own, and the neutral's (for a take that is not the
#: neutral: the neutral's landmarks and fit read its own parts only).
READS = {
    "ingest": ((), ()),
    "repair": (("ingest",), ()),
    "landmarks": (("repair",), ("repair", "landmarks")),
    "fit": (("repair", "landmarks"), ("landmarks",)),
    "align": (("fit",), ("fit",)),
    "refine": (("repair", "landmarks", "fit", "align"), ("repair", "landmarks", "fit")),
}


def neutral_reads(own, stage):
    """The neutral's parts ``stage`` reads (``own``: the take is the neutral)."""
    return () if own and stage in ("landmarks", "fit") else READS[stage][1]


def job_context(snakemake):
    """What the stages read: the job's wildcards, params, inputs and outputs, the stages'
    Params, every stage's input part files and the template (loaded once, when first asked)."""
    w, inp, out = snakemake.wildcards, snakemake.input, snakemake.output
    own = w.take == snakemake.params.take["neutral"]
    # the neutral's parts: its own for the neutral (its job writes them), none without a neutral
    has_neutral = own or hasattr(inp, "neutral_fit")

    def neutral(s):
        return out[s] if own else inp[f"neutral_{s}"]

    reads = {
        stage: [out[s] for s in mine]
        + ([neutral(s) for s in neutral_reads(own, stage)] if has_neutral else [])
        for stage, (mine, _) in READS.items()
    }
    return SimpleNamespace(
        w=w,
        p=snakemake.params,
        inp=inp,
        out=out,
        own=own,
        params=functools.cache(lambda stage: MODULES[stage].Params.from_config(snakemake.config)),
        config=snakemake.config,
        reads=reads,
        template=functools.cache(lambda: load_template(inp.template)),
    )


def stage_reads(j, stage, prints, neutral_prints, sources):
    """What a stage's fingerprint is made of besides its Params: its take's ids, the
    fingerprints of the parts it reads (the neutral's under ``neutral_``), the files' checksums
    (``sources``: the input files for ingest, the template and this script for all) and its
    code's fingerprint (``params.code``)."""
    reads = {"take": j.p.take, "script": sources["script"], "code": j.p.code[stage]}
    reads |= {s: prints.get(s) for s in READS[stage][0]}
    reads |= {f"neutral_{s}": neutral_prints.get(s) for s in neutral_reads(j.own, stage)}
    if stage == "ingest":  # the row as it is, not where it is in which sheet
        row = {k: v for k, v in j.p.row.items() if k not in ROW_LOCATION}
        reads |= {"row": row, "roles": j.p.roles, "files": sources["files"]}
        reads["problem"] = j.problem
    if stage in ("landmarks", "fit", "align", "refine"):
        reads["template"] = sources["template"]
    return reads


def print_params(j, stage):
    """The settings a stage's fingerprint holds: its ``Params``; for ingest the settings that
    reach the take, its modality's (so that changing the stereo settings re-ingests only stereo
    takes, as the job's params did); a config its ``Params`` refuse: its sections and why (the
    stage then refuses the take, as it did with its own job)."""
    try:
        params = j.params(stage)
    except InputError as exc:
        sections = {s: j.config.get(s) for s in MODULES[stage].SECTIONS}
        return {"sections": sections, "refused": str(exc)}
    if stage != "ingest":
        return params
    return {
        "stereo": j.p.stereo,
        "mesh_camera": j.p.mesh_camera,
        "depth_fusion": params.fusion if j.p.row.get("modality") == "rgbd" else None,
    }


def file_checksums(j, scriptdir, files):
    """SHA-256 of the files the stages read besides parts: this script, the template and the
    take's input ``files`` (:func:`input_files`)."""
    return {
        "script": sha256_file(Path(scriptdir) / "take.py"),
        "template": sha256_file(j.inp.template),
        # the files that exist (a missing one is the check's problem: ingest refuses the take),
        # a mesh's MTL and texture with it
        "files": check.input_checksums(files),
    }


def input_files(j):
    """The take's input files that exist, by sheet column (a column of several: a list)."""
    return {
        role: j.inp[role] if isinstance(j.inp[role], str) else list(j.inp[role])
        for role in j.p.roles
        if hasattr(j.inp, role)
    }


def run_stage(j, stage):
    """Run one stage with take isolation."""
    run_take_job(
        j.p.logs[stage],
        lambda: RUN[stage](j),
        take=j.w.take,
        stage=stage,
        inputs=j.reads[stage],
        part=j.out[stage],
        on_failure=on_failure(j, stage),
    )


def main(snakemake):
    j = job_context(snakemake)
    files = input_files(j)
    sources = file_checksums(j, snakemake.scriptdir, files)
    # the verdict on the take ('': none): the subject's check job's, when it read these files
    take = Take.from_row(j.p.row, files=files)
    report = json.loads(Path(j.inp.check).read_text())
    j.problem = check.take_verdict(report, take, j.p.problems, sources["files"])
    # the neutral's fingerprints: its job's record (for the neutral: this job's own, as it goes)
    neutral_prints = {} if j.own else read_fingerprints(j.inp.get("neutral_stages", ""))

    def plan(stage, prints):
        reads = stage_reads(j, stage, prints, prints if j.own else neutral_prints, sources)
        return fingerprint(stage, print_params(j, stage), reads), outputs(j, stage)

    run_stages(
        [s for s in TAKE_STAGES if hasattr(j.out, s)],  # refine.method none: no refine
        plan,
        lambda stage: run_stage(j, stage),
        j.out.stages,
        snakemake.log[0],
        benchmarks=j.p.benchmarks,
        done=j.out.job,
    )


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
