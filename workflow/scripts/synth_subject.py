"""Generate every take of one synthetic subject: range takes (range scan + color + landmarks +
truth) and stereo takes (left/right images + calibration + landmarks + truth)."""

import logging

from scan2morph.jobs import run_job
from scan2morph.synth import make_stereo_take, make_take, write_stereo_take, write_take


def main(snakemake):
    def job():
        subject, p, out = snakemake.wildcards.subject, snakemake.params, snakemake.output
        n_range = n_stereo = 0
        for i, t in enumerate(p.takes):
            args = (subject, t["label"], t["kind"], t["take"])
            files = (out.landmarks[i], out.truth[i])
            if t["modality"] == "stereo":
                result = make_stereo_take(*args, seed=p.seed, params=dict(p.rig))
                k, n_stereo = n_stereo, n_stereo + 1
                write_stereo_take(result, out.left[k], out.right[k], out.calibration[k], *files)
            else:
                result = make_take(*args, seed=p.seed, params=dict(p.scanner))
                k, n_range = n_range, n_range + 1
                write_take(result, out.xyz[k], out.color[k], *files)
            logging.info(
                "%s/%s: %s %s %s written", subject, t["take"], t["modality"], t["kind"], t["label"]
            )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
