# Parameter sweeps, run on demand (`snakemake sweep_all`), not by `rule all`: for each row of the
# sweep table (config key `sweeps`, one column per swept config path) and each synthetic subject,
# the stages from the first one that reads a swept key are re-run on the subject's stored parts
# and measured against the ground truth (scan2morph.sweep). The table is checked against
# the config schema when the workflow loads: a bad column or value stops the run before any job
# (workflow/rules/sweep_inputs.smk).
import re


rule sweep:
    """Re-run the stages of one synthetic subject with one sweep combination's config values and measure the accuracy."""
    input:
        store="results/{subject}/{subject}.h5",
        job="results/{subject}/job.json",
        raw=get_sweep_raw,
        truths=get_truth_files,
        template="resources/template.npz",
    output:
        f"results/sweeps/{SWEEP_SPACE.wildcard_pattern}/{{subject}}/accuracy.json",
    log:
        "logs/sweep/{params}/{subject}.log",
    benchmark:
        "benchmarks/rules/sweep/{params}/{subject}.tsv"
    wildcard_constraints:
        params="|".join(map(re.escape, SWEEP_ROWS)) if SWEEP_ROWS else "^$",
        subject="|".join(synthetic_subjects()) if synthetic_subjects() else "^$",
    resources:
        mem_mb=2000,
    params:
        row=get_sweep_row,
        settings=get_sweep_settings,
        start=SWEEP_TABLE.first_stage if SWEEP_TABLE else "",
        kinds=get_take_kinds,
        labels=get_take_labels,
    script:
        "../scripts/sweep.py"


rule sweep_summary:
    """Collect the accuracy of every sweep combination into a table and plot."""
    input:
        get_sweep_results,
    output:
        table=report(
            "results/sweeps/summary.tsv",
            caption="../report/sweep_table.rst",
            category="Parameter sweep",
        ),
        plot=report(
            "results/sweeps/summary.png",
            caption="../report/sweep_plot.rst",
            category="Parameter sweep",
        ),
    log:
        "logs/sweep_summary/sweep_summary.log",
    params:
        results=get_sweep_result_rows,
        columns=list(SWEEP_TABLE.columns) if SWEEP_TABLE else [],
        # the config sections a sweep reads, unchanged: the default value of each swept key
        defaults=sweep_settings(config, {}),
    script:
        "../scripts/sweep_summary.py"


rule sweep_all:
    """Run the whole parameter sweep on demand; not part of the default target."""
    input:
        rules.sweep_summary.output,
