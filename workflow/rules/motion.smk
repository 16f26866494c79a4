# Viseme motion vectors: aligned viseme minus neutral, stencil mask, Laplacian smoothing;
# expression displacement fields (for the modal stage).


rule motion:
    """Compute masked, smoothed viseme motion vectors and expression displacement fields against the neutral."""
    input:
        fits=get_take_parts("fit"),
        aligns=get_take_parts("align"),
        refines=get_take_parts("refine") if REFINE else [],
        template="resources/template.npz",
    output:
        part="results/{subject}/motion.h5",
    log:
        "logs/motion/{subject}.log",
    benchmark:
        "benchmarks/rules/motion/{subject}.tsv"
    resources:
        mem_mb=600,
        runtime=1,
    params:
        kinds=get_take_kinds,
        labels=get_take_labels,
        mask=config["mask"],
        smoothing=config["smoothing"],
        template=config["template"],
        quality=config["quality"],
        refine=config["refine"],
    script:
        "../scripts/motion.py"


rule motion_noise:
    """Measure the landmark click precision and the click-noise error bar of each viseme's motion."""
    input:
        repairs=get_noise_repairs,
        aligns=get_viseme_aligns,
        motion="results/{subject}/motion.h5",
        template="resources/template.npz",
    output:
        part="results/{subject}/motion_noise.h5",
        table="results/{subject}/tables/motion_noise.tsv",
    log:
        "logs/motion_noise/{subject}.log",
    benchmark:
        "benchmarks/rules/motion_noise/{subject}.tsv"
    resources:
        mem_mb=700,
        runtime=2,
    params:
        kinds=get_take_kinds,
        labels=get_take_labels,
        noise=config["motion_noise"],
        smoothing=config["smoothing"],
        template=config["template"],
        refine=config["refine"],
        align=config["align"],
    script:
        "../scripts/motion_noise.py"
