# A subject's own stages, one job per subject after its takes (one process: the interpreter and
# imports paid once a subject): its template part, consensus (the takes refined by their shape
# registered to one another by their texture), motion (viseme motion vectors and expression
# displacement fields), motion_noise (the click-noise error bar), morph (PCA, blends, exports),
# modal (shell-FEM basis, expression coordinates), store (the versioned HDF5 file), head_meshes
# (every mesh in the head frame), accuracy (synthetic subjects: against the ground truth),
# figures and report_subject (the HTML page). Each stage writes its own files, log and
# benchmark as before; a stage whose files are up to date (its fingerprint in the subject's
# stages.json) is not run, so a config change re-runs only the stages it reaches. A synthetic
# subject's job is rule subject_synthetic: the same job with its accuracy.
# stage -> benchmark file: every stage's but the report's (its page lists the subject's benchmark
# files and cannot hold its own)
SUBJECT_BENCHMARKS = stage_files(
    "benchmarks/rules/{stage}/{subject}.tsv",
    [s for s in SUBJECT_STAGES if s != "report_subject"],
)


rule subject:
    """Run a subject's own stages (template part to report) in one process, each only when its files are out of date."""
    input:
        parts=get_subject_take_parts,
        # the take jobs' fingerprints of their parts (what a stage read)
        records=get_subject_take_records,
        jobs=get_subject_take_jobs,
        template="resources/template.npz",
        layout=LAYOUT,
        captions=get_figure_captions,
    output:
        **subject_outputs(truth=False),
    log:
        "logs/subject/{subject}.log",
    benchmark:
        "benchmarks/subjects/{subject}.tsv"
    wildcard_constraints:
        subject="|".join(measured_subjects()) or "^$",
    # measured (docs/cluster.md): 1.5 x the figures' 872 MB + 400 for Snakemake; 3 x 164 s + 30 s
    # on a loaded machine, rounded up
    resources:
        mem_mb=1800,
        runtime=15,
    params:
        kinds=get_take_kinds,
        labels=get_take_labels,
        reads=get_subject_stage_reads,
        stages=lambda w: list(subject_stage_outputs(w.subject in synthetic_subjects())),
        outputs=lambda w: {
            s: list(files)
            for s, files in subject_stage_outputs(
                w.subject in synthetic_subjects()
            ).items()
        },
        figure_stages=list(FIGURE_NAMES),
        figures=get_subject_figures,
        config_sha256=CONFIG_SHA256,
        timings="benchmarks/rules",
        stage_order=get_rule_order,
        code=code_prints(SUBJECT_STAGES),
        logs=stage_files("logs/{stage}/{subject}.log", SUBJECT_STAGES),
        benchmarks=SUBJECT_BENCHMARKS,
    script:
        "../scripts/subject.py"


use rule subject as subject_synthetic with:
    input:
        parts=get_subject_take_parts,
        records=get_subject_take_records,
        jobs=get_subject_take_jobs,
        template="resources/template.npz",
        layout=LAYOUT,
        captions=get_figure_captions,
        truths=get_truth_files,
    output:
        **subject_outputs(truth=True),
    wildcard_constraints:
        subject="|".join(synthetic_subjects()) or "^$",
