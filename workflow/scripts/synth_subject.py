"""Generate every take of one synthetic subject (range scans or stereo pairs, clicks, truth)."""

from scan2morph.jobs import run_job
from scan2morph.stages import synth

ROLES = ("xyz", "color", "left", "right", "calibration", "landmarks", "truth")


def main(snakemake):
    def job():
        p, out = snakemake.params, snakemake.output
        files = {role: list(getattr(out, role)) for role in ROLES}
        synth.run(snakemake.wildcards.subject, p.takes, p.seed, p.scanner, p.rig, files)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
