# Ingest: one take's input files -> arrays on the shared pixel grid, with input checksums.


rule check_subject:
    output:
        "results/{subject}/check.json",
    params:
        problems=get_subject_problems,
    log:
        "logs/check_subject/{subject}.log",
    script:
        "../scripts/check_subject.py"


rule ingest:
    input:
        unpack(get_take_inputs),
        check="results/{subject}/check.json",
    output:
        part="results/{subject}/takes/{take}/ingest.h5",
    params:
        row=take_row,
    log:
        "logs/ingest/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/ingest/{subject}/{take}.tsv"
    resources:
        mem_mb=1000,
    script:
        "../scripts/ingest.py"
