# Store: merge the stages' parts into the versioned per-subject HDF5 file.


rule store:
    """Merge the subject's stage parts into its versioned HDF5 store, checked against the layout."""
    input:
        parts=get_subject_parts,
        layout=LAYOUT,
    output:
        "results/{subject}/{subject}.h5",
    log:
        "logs/store/{subject}.log",
    benchmark:
        "benchmarks/rules/store/{subject}.tsv"
    resources:
        mem_mb=500,
        runtime=1,
    params:
        kinds=get_take_kinds,
        labels=get_take_labels,
        config_sha256=CONFIG_SHA256,
        quality=config["quality"],
    script:
        "../scripts/store.py"
