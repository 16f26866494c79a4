# Landmarks: each take's 68 iBUG points, clicked (its landmark file) or detected on its grid.


rule landmarks:
    """Settle one take's 68 landmarks: its clicks, or detected where its sheet row gives none (or only the 51 inner points); also written as an iBUG .pts file to correct and feed back."""
    input:
        part="results/{subject}/takes/{take}/repair.h5",
        # another take's detected stable points are carried over from the neutral's
        neutral=get_neutral_parts_for_others(("repair", "landmarks")),
    output:
        part="results/{subject}/takes/{take}/landmarks.h5",
        pts="results/{subject}/landmarks/{take}.pts",
    log:
        "logs/landmarks/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/landmarks/{subject}/{take}.tsv"
    resources:
        mem_mb=800,
        runtime=2,
    params:
        take=get_take_ids,
        landmarks=config["landmarks"],
    script:
        "../scripts/landmarks.py"
