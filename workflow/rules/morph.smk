# Morphable models (Yano-Harada 5): PCA over neutral + viseme models, blends, exports.


rule morph:
    """Build the subject's morphable model: PCA over neutral and viseme meshes, blends, glTF and OBJ exports."""
    input:
        motion="results/{subject}/motion.h5",
        neutral_fit=get_neutral_fit,
        neutral_repair=get_neutral_repair,
        template="resources/template.npz",
    output:
        part="results/{subject}/morph.h5",
        eigen=report(
            "results/{subject}/tables/pca_eigenvalues.tsv",
            caption="../report/pca_eigenvalues.rst",
            category="Morphable model",
        ),
        coefficients=report(
            "results/{subject}/tables/pca_coefficients.tsv",
            caption="../report/pca_coefficients.rst",
            category="Morphable model",
        ),
        glb="results/{subject}/{subject}.glb",
        models=directory("results/{subject}/meshes/models"),
    log:
        "logs/morph/{subject}.log",
    benchmark:
        "benchmarks/rules/morph/{subject}.tsv"
    resources:
        mem_mb=700,
        runtime=2,
    params:
        kinds=get_take_kinds,
        labels=get_take_labels,
        morph=config["morph"],
        template=config["template"],
    script:
        "../scripts/morph.py"


rule head_meshes:
    """Write every mesh of the subject (aligned takes, models, expressions) in the head frame for DCC tools: metres, +Y up, +Z out of the face, textured, holes filled."""
    input:
        store="results/{subject}/{subject}.h5",
    output:
        meshes=directory("results/{subject}/meshes/head"),
    log:
        "logs/head_meshes/{subject}.log",
    benchmark:
        "benchmarks/rules/head_meshes/{subject}.tsv"
    resources:
        mem_mb=600,
        runtime=1,
    script:
        "../scripts/head_meshes.py"
