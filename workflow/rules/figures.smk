# Figures of every stage (scan2morph.render.figures), drawn from the subject's store.


rule figures_fit:
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("fit"),
    log:
        "logs/figures_fit/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_fit/{subject}.tsv"
    resources:
        mem_mb=1500,
    params:
        stage="fit",
    script:
        "../scripts/figures.py"


rule figures_motion:
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("motion"),
    log:
        "logs/figures_motion/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_motion/{subject}.tsv"
    resources:
        mem_mb=1500,
    params:
        stage="motion",
    script:
        "../scripts/figures.py"


rule figures_morph:
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("morph"),
    log:
        "logs/figures_morph/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_morph/{subject}.tsv"
    resources:
        mem_mb=1500,
    params:
        stage="morph",
    script:
        "../scripts/figures.py"


rule figures_modal:
    input:
        store="results/{subject}/{subject}.h5",
    output:
        **figure_outputs("modal"),
    log:
        "logs/figures_modal/{subject}.log",
    benchmark:
        "benchmarks/rules/figures_modal/{subject}.tsv"
    resources:
        mem_mb=1500,
    params:
        stage="modal",
    script:
        "../scripts/figures.py"
