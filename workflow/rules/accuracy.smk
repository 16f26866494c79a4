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
    params:
        takes=get_takes,
        neutral=get_neutral_take,
        visemes=get_viseme_takes,
        fiducial_sets=get_fiducial_sets,
        levels=config["template"]["subdivision_levels"],
        smoothing=config["smoothing"],
        max_slope_deg=config["template"]["max_slope_deg"],
    script:
        "../scripts/accuracy.py"
