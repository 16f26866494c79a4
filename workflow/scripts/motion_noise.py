"""Click-noise sensitivity of each viseme's motion (an error bar without ground truth)."""

import logging

import pandas as pd

from scan2morph.jobs import run_job
from scan2morph.motion.uncertainty import click_noise_motion, clicked_take, noise_datasets
from scan2morph.store import read_part, write_part
from scan2morph.template import fit_options, load_template

COLUMNS = {
    "motion_rms_mm": "motion_rms_mm",
    "rms_error_mm": "noise_rms_mm",
    "relative": "noise_relative",
    "failed_draws": "failed_draws",
}


def main(snakemake):
    def job():
        p, inp, out = snakemake.params, snakemake.input, snakemake.output
        store = read_part(inp.neutral)
        for path in [*inp.visemes, *inp.aligns]:
            store |= read_part(path)
        result = click_noise_motion(
            load_template(inp.template),
            clicked_take(store, p.neutral, p.fiducials[p.neutral]),
            {t: clicked_take(store, t, p.fiducials[t]) for t in p.visemes},
            read_part(inp.motion)["/mask/suppressed"],
            p.smoothing,
            fit_options(p.template),
            p.noise["click_noise_px"],
            p.noise["draws"],
            p.noise["seed"],
            source=snakemake.wildcards.subject,
        )
        for take, r in result.items():
            logging.info("%s: click noise moves the motion by %.1f%%", take, 100 * r["relative"])
        attrs = {"/motion_noise": {k: p.noise[k] for k in ("click_noise_px", "draws", "seed")}}
        write_part(out.part, noise_datasets(result), attrs=attrs)
        rows = [{"take": t, **{c: r[k] for k, c in COLUMNS.items()}} for t, r in result.items()]
        table = pd.DataFrame(rows, columns=["take", *COLUMNS.values()])
        table.to_csv(out.table, sep="\t", index=False, float_format="%.6g")

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
