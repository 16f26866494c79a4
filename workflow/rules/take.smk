# A take's stages, one job per take (one process: the interpreter and imports paid once a take):
# ingest (stereo reconstructed, RGB-D depth resampled onto the colour image, a mesh rendered),
# repair (Yano-Harada 3.1), landmarks, fit (TPS warp to fiducials, subdivision), align to the
# neutral (Kabsch, then ICP on the still skin) and refine (image correlation of the skin against
# the neutral; refine.method: none keeps the template fit). Each stage writes its own part, log
# and benchmark as before; a stage whose part is up to date (its fingerprint in stages.json) is
# not run again, so a config change re-runs only the stages it reaches.

REFINE = config["refine"]["method"] != "none"
# the take's stages and their parts (refine.method: none keeps the template fit: no refine part);
# update: a part is kept when the job starts, rewritten only by the stage that writes it
TAKE_STAGES = ("ingest", "repair", "landmarks", "fit", "align") + (
    ("refine",) if REFINE else ()
)
TAKE_PARTS = {
    s: update(f"results/{{subject}}/takes/{{take}}/{s}.h5") for s in TAKE_STAGES
}


rule check_subject:
    """Check every sheet row and input file of a subject at once (cheap reads): stop the subject on its own or its neutral's problems, name the takes to leave out."""
    input:
        # the takes' files ancient: a file's new content is checked by its own take's job
        # (check.take_verdict), which re-runs for it; this job re-runs for a new sheet row or
        # file, and for the neutral's new content (a problem of it stops the subject)
        get_check_inputs,
    output:
        "results/{subject}/check.json",
    log:
        "logs/check_subject/{subject}.log",
    benchmark:
        "benchmarks/rules/check_subject/{subject}.tsv"
    resources:
        # a mesh scan adds what reading it takes (50 MB per MB of a PLY or GLB, docs/cluster.md)
        mem_mb=lambda wildcards, input: memory_mb(input, 500),
        runtime=1,
    params:
        problems=get_subject_problems,
        rows=get_subject_rows,
        files=get_subject_files,
    script:
        "../scripts/check_subject.py"


rule take:
    """Run one take's stages in one process, each only when its part is out of date; the other takes of the subject wait for the neutral's."""
    input:
        unpack(get_take_job_inputs),
        # not ancient: Snakemake (9.27) skipped a take whose ancient input's job re-ran, even
        # when the take's own file had changed, until a second run; check.json is rewritten only
        # when the sheet's rows or files change (and a take whose parts are up to date then
        # runs no stage)
        check="results/{subject}/check.json",
        template="resources/template.npz",
    output:
        **TAKE_PARTS,
        repair_report=update("results/{subject}/takes/{take}/repair.json"),
        pts=update("results/{subject}/landmarks/{take}.pts"),
        xyz=update("results/{subject}/landmarks/{take}.xyz"),
        obj=update("results/{subject}/meshes/{take}.obj"),
        mtl=update("results/{subject}/meshes/{take}.mtl"),
        texture=update("results/{subject}/meshes/{take}.png"),
        stages=update("results/{subject}/takes/{take}/stages.json"),
        # not update: deleted when the job starts, so a job that failed (its update() files put
        # back with a new time) runs again
        job="results/{subject}/takes/{take}/job.json",
    log:
        "logs/take/{subject}/{take}.log",
    benchmark:
        "benchmarks/takes/{subject}/{take}.tsv"
    resources:
        mem_mb=lambda wildcards, input: memory_mb(input, 900),
        runtime=12,
    params:
        row=take_row,
        stamps=get_take_stamps,
        problems=get_take_problems,
        roles=get_take_roles,
        stereo=get_stereo_params,
        mesh_camera=get_mesh_camera_params,
        take=get_take_ids,
        repair=config["repair"],
        landmarks=config["landmarks"],
        template=config["template"],
        align=config["align"],
        refine=config["refine"],
        code=code_prints(TAKE_STAGES),
        logs=stage_files("logs/{stage}/{subject}/{take}.log", TAKE_STAGES),
        benchmarks=stage_files(
            "benchmarks/rules/{stage}/{subject}/{take}.tsv", TAKE_STAGES
        ),
    script:
        "../scripts/take.py"
