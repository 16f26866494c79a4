# The 2D template mesh the takes are fitted with (Yano-Harada 3.1); each subject's copy of it is
# written by the subject's job (subject.smk).


rule template:
    """Build the 2D template mesh with its fiducial sets."""
    output:
        "resources/template.npz",
    log:
        "logs/template/template.log",
    benchmark:
        "benchmarks/rules/template/template.tsv"
    resources:
        mem_mb=600,
        runtime=5,
    params:
        # the library's fiducial sets, saved with the template: a change rebuilds it
        fiducial_sets=FIDUCIAL_SETS,
        code=code_prints(["template"]),
    script:
        "../scripts/template.py"
