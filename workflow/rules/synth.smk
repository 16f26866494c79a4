# Synthetic subjects with exact ground truth, written in the formats users bring.


def get_synth_take(wildcards):
    return TAKES.loc[(wildcards.subject, wildcards.take), ["kind", "label"]].to_dict()


rule synth_take:
    output:
        xyz=f"{SYNTH_ROOT}/{{subject}}/{{take}}.abs.gz",
        color=f"{SYNTH_ROOT}/{{subject}}/{{take}}.png",
        landmarks=f"{SYNTH_ROOT}/{{subject}}/{{take}}.pts",
        truth=f"{SYNTH_ROOT}/{{subject}}/truth/{{take}}.npz",
    params:
        take=get_synth_take,
        seed=config["synthetic"]["seed"],
        scanner=config["synthetic"]["scanner"],
    log:
        "logs/synth_take/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/synth_take/{subject}/{take}.tsv"
    resources:
        mem_mb=1000,
    script:
        "../scripts/synth_take.py"
