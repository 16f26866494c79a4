# Rigid alignment of each take to the neutral: point pairs (Kabsch), then ICP on the upper face.


rule align:
    """Rigidly align one take's fitted mesh to the subject's neutral: Kabsch on point pairs, then ICP on the upper face."""
    input:
        take="results/{subject}/takes/{take}/fit.h5",
        neutral=get_neutral_fit,
        template="resources/template.npz",
    output:
        part="results/{subject}/takes/{take}/align.h5",
    log:
        "logs/align/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/align/{subject}/{take}.tsv"
    resources:
        mem_mb=900,
        runtime=2,
    params:
        take=get_take_ids,
        align=config["align"],
        template=config["template"],
    script:
        "../scripts/align.py"
