# Template fitting (Yano-Harada 3.1): TPS warp to fiducials, subdivision, bilinear sampling.


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


rule fit:
    """Fit the template mesh to one take's range image by TPS warp to the fiducials and subdivision; export it as OBJ."""
    input:
        part="results/{subject}/takes/{take}/repair.h5",
        landmarks="results/{subject}/takes/{take}/landmarks.h5",
        template="resources/template.npz",
    output:
        part="results/{subject}/takes/{take}/fit.h5",
        obj="results/{subject}/meshes/{take}.obj",
        mtl="results/{subject}/meshes/{take}.mtl",
        texture="results/{subject}/meshes/{take}.png",
    log:
        "logs/fit/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/fit/{subject}/{take}.tsv"
    resources:
        mem_mb=700,
        runtime=2,
    params:
        take=get_take_ids,
        template=config["template"],
    script:
        "../scripts/fit.py"
