"""Run a subject's own stages in one process: its template part, consensus, motion, motion_noise, morph,
modal, store, head_meshes, accuracy (synthetic subjects), figures and report_subject.

A stage whose files are up to date (its fingerprint, :mod:`scan2morph.stages.stage_job`) is not
run; one that runs writes its files, its log and its benchmark as its own job did. A stage that
fails stops the job with one line naming the subject and the stage; the stages after it do not
run (Snakemake puts back the files the job found).
"""

import functools
import json
import logging
import shutil
import sys
from pathlib import Path
from types import SimpleNamespace

from scan2morph.errors import InputError
from scan2morph.jobs import run_job, sha256_file, write_json
from scan2morph.stages import Subject
from scan2morph.stages.stage_job import fingerprint, part_fingerprint, run_stages
from scan2morph.store import paths, read_group_attrs, read_part, read_parts, write_part
from scan2morph.template import load_template

#: The subject's own stages each stage reads (besides the take parts it reads: params.reads).
OWN_READS = {
    "template_part": (),
    "consensus": (),
    "motion": ("consensus",),
    "motion_noise": ("motion", "consensus"),
    "morph": ("motion",),
    "modal": ("motion",),
    "store": ("template_part", "consensus", "motion", "motion_noise", "morph", "modal"),
    "head_meshes": ("store",),
    "accuracy": ("store",),
    "figures": ("store",),
    "report_subject": ("store", "morph", "figures", "accuracy"),
}

#: The stages that read the template.
TEMPLATE = ("template_part", "consensus", "motion", "motion_noise", "morph", "modal", "accuracy")


def stage_module(stage):
    """The library module of a stage (imported when first needed)."""
    import importlib

    name = {"template_part": "fit", "report_subject": "report"}.get(stage, stage)
    return importlib.import_module(f"scan2morph.stages.{name}")


def run_template_part(j):
    """The faces and fiducials of the subdivided template."""
    fit = stage_module("template_part")
    part = fit.template_part(j.template(), j.params("template_part"))
    write_part(j.out.template_part, part.datasets)


def refine_verdicts(files):
    """Each take's refine group attributes (whether its texture correlated, or its shape refined
    it), from its refine part (``.../takes/{take}/refine.h5``), under the group's store path; a
    take left out has none."""
    refines = {Path(f).parent.name: f for f in files if Path(f).name == "refine.h5"}
    return read_group_attrs(refines, paths.refine_group)


def run_consensus(j):
    """The takes refined by their shape registered to one another by their shared texture (the
    parts read only when enough takes were: the verdicts alone say why not)."""
    reads, consensus = j.p.reads["consensus"], stage_module("consensus")
    data = refine_verdicts(reads)
    enough = len(consensus.members(j.subject, data)) >= consensus.MIN_TAKES
    if j.params("consensus").use and enough:
        data |= read_parts(reads)
    part = consensus.run(j.template(), j.subject, data, j.params("consensus"))
    write_part(j.out.consensus, part.datasets, attrs=part.attrs)


def run_motion(j):
    """Viseme motion (mask, smoothing, models) and expression displacement fields."""
    data = read_parts([*j.p.reads["motion"], j.out.consensus])
    part = stage_module("motion").run(j.template(), j.subject, data, j.params("motion"))
    write_part(j.out.motion, part.datasets)


def run_motion_noise(j):
    """Click precision and the click-noise error bar of each viseme's motion."""
    from scan2morph.tables import MOTION_NOISE, write_table

    reads = j.p.reads["motion_noise"]
    own = [f for f in reads if Path(f).name != "refine.h5"]
    data = read_parts([*own, j.out.motion, j.out.consensus])
    # the pipeline's verdict on each viseme's texture (refined by it, or by the shape)
    data |= refine_verdicts(reads)
    module = stage_module("motion_noise")
    part = module.run(j.template(), j.subject, data, j.params("motion_noise"))
    write_part(j.out.motion_noise, part.datasets, attrs=part.attrs)
    write_table(j.out.motion_noise_table, part.files["table"], MOTION_NOISE)


def run_morph(j):
    """PCA, blends and exports (glTF with morph targets, OBJ per model and blend)."""
    out, morph = j.out, stage_module("morph")
    data = read_parts([out.motion, *j.p.reads["morph"]])
    part = morph.run(j.template(), j.subject, data, j.params("morph"))
    write_part(out.morph, part.datasets, attrs=part.attrs)
    morph.write_files(part, out.eigen, out.coefficients, out.glb, out.models)


def run_modal(j):
    """Modal basis of the neutral face and expression coordinates."""
    out, modal = j.out, stage_module("modal")
    params = j.params("modal").with_threads(j.threads)
    part = modal.run(j.template(), j.subject, read_parts([out.motion, *j.p.reads["modal"]]), params)
    write_part(out.modal, part.datasets, attrs=part.attrs)
    modal.write_files(part, out.coordinates, out.reconstruction, out.expressions)


def run_store(j):
    """Merge the parts into the subject's store with its warnings, checked against the layout."""
    from scan2morph.store import load_layout
    from scan2morph.store.hdf5 import write_file

    out = j.out
    own = [out.template_part, out.consensus, out.motion, out.motion_noise, out.morph, out.modal]
    params = j.params("store").with_layout(load_layout(j.inp.layout))
    data = {"parts": [*j.p.reads["store"], *own], "code_sha256": j.p.code["store"]}
    part = stage_module("store").run(None, j.subject, data, params)
    write_file(out.store, part.files["store"])


def run_head_meshes(j):
    """Every mesh in the head frame, for DCC tools."""
    from scan2morph.morph.head import write_head_meshes

    write_head_meshes(j.out.store, j.out.head)


def run_accuracy(j):
    """Accuracy against the ground truth -> accuracy.json."""
    from scan2morph.evaluate.truth import read_truth

    accuracy = stage_module("accuracy")
    truths = {t: read_truth(f) for t, f in zip(j.p.kinds, j.inp.truths, strict=True)}
    data = read_part(j.out.store) | accuracy.truth_datasets(truths)
    part = accuracy.run(j.template(), j.subject, data, j.params("accuracy"))
    write_json(j.out.accuracy, part.files["accuracy"])


def run_figures(j):
    """Every stage's figures from the store (one reading of it, one offscreen context)."""
    from scan2morph.render.figures import write_figures

    outputs, timings = j.p.figures, {}
    written = write_figures(
        j.out.store, Path(outputs[0]).parent, j.p.figure_stages, outputs, timings
    )
    for stage, seconds in timings.items():
        logging.info("%s: figures of stage %s in %.2f s", j.subject.name, stage, seconds)
    logging.info("%s: %d figures", j.subject.name, len(written))


def run_report_subject(j):
    """The self-contained HTML page: inputs, figures, tables, accuracy and provenance."""
    from scan2morph.report import stage_timings
    from scan2morph.report.html import write_html

    out = j.out
    data = {
        "store": out.store,
        "figures": j.p.figures,
        "captions": list(j.inp.captions),
        "accuracy": json.loads(Path(out.accuracy).read_text()) if j.truth else None,
        "timings": stage_timings(j.p.timings, j.subject.name, j.p.stage_order),
        "glb": out.glb,
    }
    part = stage_module("report_subject").run(None, j.subject, data, j.params("report_subject"))
    write_html(out.report, part.files["html"])


RUN = {
    "template_part": run_template_part,
    "consensus": run_consensus,
    "motion": run_motion,
    "motion_noise": run_motion_noise,
    "morph": run_morph,
    "modal": run_modal,
    "store": run_store,
    "head_meshes": run_head_meshes,
    "accuracy": run_accuracy,
    "figures": run_figures,
    "report_subject": run_report_subject,
}


def job_context(snakemake):
    """What the stages read: the subject, the job's params, inputs and outputs, each stage's
    Params (built once, when first asked) and the template (loaded once)."""
    p, inp = snakemake.params, snakemake.input
    return SimpleNamespace(
        subject=Subject(snakemake.wildcards.subject, p.kinds, p.labels),
        p=p,
        inp=inp,
        out=snakemake.output,
        threads=snakemake.threads,
        truth=hasattr(inp, "truths"),
        config=snakemake.config,
        params=functools.cache(lambda s: stage_module(s).Params.from_config(snakemake.config)),
        template=functools.cache(lambda: load_template(inp.template)),
    )


def print_params(j, stage):
    """The settings a stage's fingerprint holds: its ``Params`` (the figures: which stages'; the
    head meshes: none); a config its ``Params`` refuse: its sections and why (the stage then
    stops the job, as it did in a job of its own)."""
    if stage == "figures":
        return {"stages": list(j.p.figure_stages)}
    if stage == "head_meshes":
        return {}
    try:
        return j.params(stage)
    except InputError as exc:
        sections = {s: j.config.get(s) for s in stage_module(stage).SECTIONS}
        return {"sections": sections, "refused": str(exc)}


def stage_reads(j, stage, prints, sources):
    """What a stage's fingerprint is made of besides its Params: the subject's takes, this
    script's checksum, its code's fingerprint (``params.code``), the fingerprints of the
    subject's stages and the take parts it reads, and the checksums of the other files it reads
    (template, layout, truths, captions)."""
    reads = {"kinds": j.p.kinds, "labels": j.p.labels, "script": sources["script"]}
    reads["code"] = j.p.code[stage]
    reads |= {s: prints.get(s) for s in OWN_READS[stage]}
    reads["parts"] = [part_fingerprint(f) for f in j.p.reads.get(stage, ())]
    if stage in TEMPLATE:
        reads["template"] = sources["template"]
    if stage == "store":
        reads["layout"] = sha256_file(j.inp.layout)
    if stage == "accuracy":
        reads["truths"] = [sha256_file(f) for f in j.inp.truths]
    if stage == "report_subject":
        reads["captions"] = [sha256_file(f) for f in j.inp.captions]
        reads["stage_order"] = list(j.p.stage_order)
    return reads


def outputs(j, stage):
    """Every file and folder ``stage`` writes for the subject."""
    return [j.out[name] for name in j.p.outputs[stage]]


def run_stage(j, stage):
    """Run one stage into its own log: its output folders are emptied first (as Snakemake did
    for the stage's own job), its files replaced."""
    for path in outputs(j, stage):
        if Path(path).is_dir():
            shutil.rmtree(path)
    run_job(j.p.logs[stage], lambda: RUN[stage](j))


def main(snakemake):
    from scan2morph.report import clear_stale

    j = job_context(snakemake)
    # the banner an earlier run's stop put on the page (common.smk, report_left_out) comes off:
    # the page is this job's again, rewritten when out of date, else kept as it was written
    clear_stale(j.out.report)
    sources = {
        "script": sha256_file(Path(snakemake.scriptdir) / "subject.py"),
        "template": sha256_file(j.inp.template),
    }

    def plan(stage, prints):
        return fingerprint(stage, print_params(j, stage), stage_reads(j, stage, prints, sources))

    def run(stage):
        try:
            run_stage(j, stage)
        except (Exception, SystemExit):
            later = j.p.stages[j.p.stages.index(stage) + 1 :]
            sys.stderr.write(
                f"{j.subject.name}: stage {stage} failed (see {j.p.logs[stage]}); "
                f"not run: {', '.join(later) or 'none'}\n"
            )
            raise

    run_stages(
        j.p.stages,
        lambda stage, prints: (plan(stage, prints), outputs(j, stage)),
        run,
        j.out.stages,
        snakemake.log[0],
        benchmarks=j.p.benchmarks,
        done=j.out.job,
    )


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
