# Figures of every stage (scan2morph.render.figures), drawn from the subject's store.


rule figures_fit:
    """Draw the template-fitting figures of a subject from its store."""
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("fit"),
    log:
        "logs/figures_fit/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_fit/{subject}.tsv"
    resources:
        mem_mb=900,
        runtime=2,
    params:
        stage="fit",
    script:
        "../scripts/figures.py"


rule figures_motion:
    """Draw the alignment and viseme-motion figures of a subject from its store."""
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("motion"),
    log:
        "logs/figures_motion/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_motion/{subject}.tsv"
    resources:
        mem_mb=900,
        runtime=3,
    params:
        stage="motion",
    script:
        "../scripts/figures.py"


rule figures_morph:
    """Draw the morphable-model figures of a subject, PCA and blends, from its store."""
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("morph"),
    log:
        "logs/figures_morph/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_morph/{subject}.tsv"
    resources:
        mem_mb=900,
        runtime=5,
    params:
        stage="morph",
    script:
        "../scripts/figures.py"


rule figures_modal:
    """Draw the modal-analysis figures of a subject, modes and expressions, from its store."""
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("modal"),
    log:
        "logs/figures_modal/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_modal/{subject}.tsv"
    resources:
        mem_mb=900,
        runtime=5,
    params:
        stage="modal",
    script:
        "../scripts/figures.py"
