# The 2D template mesh the takes are fitted with (Yano-Harada 3.1), and each subject's copy of it.


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
    script:
        "../scripts/template.py"


rule template_part:
    """Write the faces and fiducials of the subject's subdivided template as a store part."""
    input:
        template="resources/template.npz",
    output:
        part="results/{subject}/template.h5",
    log:
        "logs/template_part/{subject}.log",
    benchmark:
        "benchmarks/rules/template_part/{subject}.tsv"
    resources:
        mem_mb=600,
        runtime=1,
    params:
        template=config["template"],
    script:
        "../scripts/template_part.py"
