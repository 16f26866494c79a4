"""Generate every take of one synthetic subject (range, stereo, RGB-D or mesh; clicks; truth)."""

import logging

from scan2morph.jobs import run_job
from scan2morph.stages import Take, synth

ROLES = sorted({r for roles in synth.ROLES.values() for r in roles} | {"landmarks", "truth"})
log = logging.getLogger("scan2morph")


def main(snakemake):
    def job():
        p, out, subject = snakemake.params, snakemake.output, snakemake.wildcards.subject
        files = {role: list(getattr(out, role)) for role in ROLES}
        params = synth.Params.from_config(snakemake.config)
        frames = int(p.rgbd.get("frames", 1))
        counts = dict.fromkeys(synth.ROLES, 0)  # each modality's files are in take order
        for i, row in enumerate(p.takes):
            take = Take.from_row(row | {"subject": subject}, files={})
            k, counts[row["modality"]] = counts[row["modality"]], counts[row["modality"]] + 1
            own = {role: files[role][k] for role in synth.ROLES[row["modality"]]}
            if row["modality"] == "rgbd":  # several depth frames per take, in take order
                own["depth"] = files["depth"][k * frames : (k + 1) * frames]
            own |= {"landmarks": files["landmarks"][i], "truth": files["truth"][i]}
            synth.write_files(synth.run(None, take, params), own)
            log.info("%s: %s %s %s written", take.source, row["modality"], take.kind, take.label)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
