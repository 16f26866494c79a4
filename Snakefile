# scan2morph: 3D face scans -> subject-specific morphable face models.
# Stages (one file each under workflow/rules/): synth, ingest, repair, store.


from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/synth.smk"
include: "workflow/rules/ingest.smk"
include: "workflow/rules/repair.smk"
include: "workflow/rules/store.smk"


rule all:
    default_target: True
    input:
        get_final_outputs(),
