# Viseme motion vectors: aligned viseme minus neutral, stencil mask, Laplacian smoothing;
# expression displacement fields (for the modal stage).


rule motion:
    """Compute masked, smoothed viseme motion vectors and expression displacement fields against the neutral."""
    input:
        neutral_fit=get_neutral_fit,
        neutral_align=get_neutral_align,
        fits=get_other_fits,
        aligns=get_other_aligns,
        template="resources/template.npz",
    output:
        part="results/{subject}/motion.h5",
    log:
        "logs/motion/{subject}.log",
    benchmark:
        "benchmarks/rules/motion/{subject}.tsv"
    params:
        neutral=get_neutral_take,
        others=get_other_takes,
        visemes=get_viseme_takes,
        expressions=get_expression_takes,
        mask=config["mask"],
        smoothing=config["smoothing"],
        levels=config["template"]["subdivision_levels"],
    script:
        "../scripts/motion.py"


rule motion_noise:
    """Measure the landmark click precision and the click-noise error bar of each viseme's motion."""
    input:
        neutral=get_neutral_repair,
        visemes=get_viseme_repairs,
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
        mem_mb=1000,
    params:
        neutral=get_neutral_take,
        visemes=get_viseme_takes,
        fiducials=get_fiducial_sets,
        noise=config["motion_noise"],
        smoothing=config["smoothing"],
        template=config["template"],
    script:
        "../scripts/motion_noise.py"
