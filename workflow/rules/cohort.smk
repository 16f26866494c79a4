# The cohort summary: one row per subject and a plot comparing them (scan2morph.report.cohort).


rule cohort:
    """Summarise every subject in one cohort table and comparison plot."""
    input:
        stores=expand("results/{subject}/{subject}.h5", subject=SUBJECTS),
        # each subject's job finished (a failed one's files are put back as they were)
        jobs=expand("results/{subject}/job.json", subject=SUBJECTS),
        accuracy=expand("results/{subject}/accuracy.json", subject=synthetic_subjects()),
    output:
        table=report(
            "results/cohort/summary.tsv",
            caption="../report/cohort_table.rst",
            category="Cohort",
        ),
        plot=report(
            "results/cohort/summary.png",
            caption="../report/cohort_plot.rst",
            category="Cohort",
        ),
    log:
        "logs/cohort/cohort.log",
    benchmark:
        "benchmarks/rules/cohort/cohort.tsv"
    params:
        subjects=SUBJECTS,
        accuracy_subjects=synthetic_subjects(),
        code=code_prints(["cohort"]),
    script:
        "../scripts/cohort.py"
