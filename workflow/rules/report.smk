# The per-subject report page (scan2morph.report.html): inputs, figures, PCA and modal tables,
# accuracy and provenance in one self-contained HTML file.


rule report_subject:
    """Write the subject's self-contained HTML report: inputs, figures, tables, accuracy and provenance."""
    input:
        store="results/{subject}/{subject}.h5",
        glb="results/{subject}/{subject}.glb",
        figures=get_subject_figures,
        captions=get_figure_captions,
        accuracy=get_subject_accuracy,
    output:
        report(
            "results/{subject}/report.html",
            caption="../report/subject_report.rst",
            category="Subject reports",
            labels={"subject": "{subject}"},
        ),
    log:
        "logs/report_subject/{subject}.log",
    resources:
        mem_mb=800,
        runtime=2,
    params:
        benchmarks="benchmarks/rules",
        stage_order=get_rule_order,
        kinds=get_take_kinds,
        labels=get_take_labels,
        report=config["report"],
    script:
        "../scripts/report_subject.py"
