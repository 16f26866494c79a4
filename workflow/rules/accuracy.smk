# Accuracy against ground truth (synthetic subjects only: they are the ones with truth files).


rule accuracy:
    """Measure a synthetic subject's fits, motion and models against the ground truth."""
    input:
        store="results/{subject}/{subject}.h5",
        truths=get_truth_files,
        template="resources/template.npz",
    output:
        report(
            "results/{subject}/accuracy.json",
            caption="../report/accuracy.rst",
            category="Accuracy",
        ),
    log:
        "logs/accuracy/{subject}.log",
    benchmark:
        "benchmarks/rules/accuracy/{subject}.tsv"
    resources:
        mem_mb=1900,
        runtime=4,
    params:
        kinds=get_take_kinds,
        labels=get_take_labels,
        template=config["template"],
        smoothing=config["smoothing"],
    script:
        "../scripts/accuracy.py"
