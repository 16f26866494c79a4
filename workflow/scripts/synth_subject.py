"""Generate every take of one synthetic subject (range, stereo, RGB-D or mesh; clicks; truth)."""

from scan2morph.jobs import run_job
from scan2morph.stages import synth

ROLES = sorted({r for roles in synth.ROLES.values() for r in roles} | {"landmarks", "truth"})


def main(snakemake):
    def job():
        p, out = snakemake.params, snakemake.output
        files = {role: list(getattr(out, role)) for role in ROLES}
        sensors = {"rgbd": p.rgbd, "mesh": p.mesh}
        synth.run(snakemake.wildcards.subject, p.takes, p.seed, p.scanner, p.rig, files, sensors)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
