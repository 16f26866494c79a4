# Figures of every stage (scan2morph.render.figures), drawn from the subject's store in one job:
# one interpreter, one reading of the store and one offscreen context for all of them (each
# stage's own drawing time is in the job's log).


rule figures:
    """Draw every stage's figures of a subject (fit, motion, morph, modal) from its store."""
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **{k: v for stage in FIGURE_NAMES for k, v in figure_outputs(stage).items()},
    log:
        "logs/figures/{subject}.log",
    benchmark:
        "benchmarks/rules/figures/{subject}.tsv"
    resources:
        mem_mb=900,
        runtime=10,
    params:
        stages=list(FIGURE_NAMES),
    script:
        "../scripts/figures.py"
