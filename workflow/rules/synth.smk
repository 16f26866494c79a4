# Synthetic subjects with exact ground truth, written in the formats users bring.
# One job per subject: the procedural head is built once and rendered for every take.


rule synth_subject:
    output:
        xyz=expand(f"{SYNTH_ROOT}/{{{{subject}}}}/{{take}}.abs.gz", take=SYNTH_TAKES),
        color=expand(f"{SYNTH_ROOT}/{{{{subject}}}}/{{take}}.png", take=SYNTH_TAKES),
        landmarks=expand(f"{SYNTH_ROOT}/{{{{subject}}}}/{{take}}.pts", take=SYNTH_TAKES),
        truth=expand(f"{SYNTH_ROOT}/{{{{subject}}}}/truth/{{take}}.npz", take=SYNTH_TAKES),
    params:
        takes=config["synthetic"]["takes"],
        seed=config["synthetic"]["seed"],
        scanner=config["synthetic"]["scanner"],
    log:
        "logs/synth_subject/{subject}.log",
    benchmark:
        "benchmarks/rules/synth_subject/{subject}.tsv"
    resources:
        mem_mb=2000,
    script:
        "../scripts/synth_subject.py"
