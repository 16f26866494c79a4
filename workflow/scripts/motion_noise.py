"""Click precision and the click-noise error bar of each viseme's motion (no ground truth)."""

import logging

import pandas as pd

from scan2morph.jobs import run_job
from scan2morph.motion.uncertainty import subject_motion_noise
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
        subject = snakemake.wildcards.subject
        store = read_part(inp.neutral) | read_part(inp.motion, "/mask")
        for path in [*inp.visemes, *inp.aligns]:
            store |= read_part(path)
        data, result, noise = subject_motion_noise(
            load_template(inp.template),
            store,
            p.neutral,
            p.visemes,
            p.fiducials,
            p.smoothing,
            fit_options(p.template),
            p.noise,
            source=subject,
        )
        logging.info("%s: click noise %s", subject, noise["note"])
        for take, name, r in noise["misclicks"]:
            logging.warning(
                "%s/%s: landmark %d is %.1f px off the others (mis-click?)", subject, take, name, r
            )
        for take, r in result.items():
            logging.info("%s: click noise moves the motion by %.1f%%", take, 100 * r["relative"])
        attrs = {
            "/motion_noise": {
                "draws": p.noise["draws"],
                "seed": p.noise["seed"],
                "click_noise_source": noise["source"],
                "click_noise_note": noise["note"],
                "misclicks": [list(m) for m in noise["misclicks"]],
            }
        }
        write_part(out.part, data, attrs=attrs)
        rows = [{"take": t, **{c: r[k] for k, c in COLUMNS.items()}} for t, r in result.items()]
        table = pd.DataFrame(rows, columns=["take", *COLUMNS.values()])
        table["click_noise_px"] = noise["click_noise_px"]
        table.to_csv(out.table, sep="\t", index=False, float_format="%.6g")

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
