# Modal basis of the neutral face (shell FEM) and expression coordinates (modal analysis paper).


rule modal:
    """Compute the shell-FEM modal basis of the neutral face and the expressions' modal coordinates."""
    input:
        motion="results/{subject}/motion.h5",
        template="resources/template.npz",
    output:
        part="results/{subject}/modal.h5",
        coordinates=report(
            "results/{subject}/tables/modal_coordinates.tsv",
            caption="../report/modal_coordinates.rst",
            category="Modal analysis",
        ),
        reconstruction=report(
            "results/{subject}/tables/modal_reconstruction.tsv",
            caption="../report/modal_reconstruction.rst",
            category="Modal analysis",
        ),
        meshes=directory("results/{subject}/meshes/expressions"),
    log:
        "logs/modal/{subject}.log",
    benchmark:
        "benchmarks/rules/modal/{subject}.tsv"
    threads: 2
    resources:
        mem_mb=900,
        runtime=2,
    params:
        kinds=get_take_kinds,
        labels=get_take_labels,
        modal=config["modal"],
        template=config["template"],
    script:
        "../scripts/modal.py"
