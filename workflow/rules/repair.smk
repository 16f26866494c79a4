# Repair: spike removal, then small-hole filling (Yano-Harada 3.1).


rule repair:
    """Repair one take's range image: remove spikes, fill small holes."""
    input:
        part="results/{subject}/takes/{take}/ingest.h5",
    output:
        part="results/{subject}/takes/{take}/repair.h5",
        report="results/{subject}/takes/{take}/repair.json",
    log:
        "logs/repair/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/repair/{subject}/{take}.tsv"
    resources:
        mem_mb=800,
        runtime=2,
    params:
        take=get_take_ids,
        repair=config["repair"],
    script:
        "../scripts/repair.py"
