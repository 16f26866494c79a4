# Correspondence refinement: each take's fit corrected by image correlation of the skin against
# the neutral, then aligned as the take was (refine.method: none keeps the template fit).


REFINE = config["refine"]["method"] != "none"


rule refine:
    """Refine one take's correspondence to the neutral by image correlation of the skin."""
    input:
        take=expand(
            "results/{{subject}}/takes/{{take}}/{stage}.h5",
            stage=("repair", "landmarks", "fit", "align"),
        ),
        neutral=get_neutral_parts(("repair", "landmarks", "fit")),
        template="resources/template.npz",
    output:
        part="results/{subject}/takes/{take}/refine.h5",
    log:
        "logs/refine/{subject}/{take}.log",
    benchmark:
        "benchmarks/rules/refine/{subject}/{take}.tsv"
    resources:
        mem_mb=900,
        runtime=2,
    params:
        take=get_take_ids,
        refine=config["refine"],
        template=config["template"],
        align=config["align"],
    script:
        "../scripts/refine.py"
