"""Repair one take's range image: spikes out, small holes filled."""

import logging

import numpy as np

from scan2morph.jobs import run_job, write_json
from scan2morph.scan import repair_range
from scan2morph.store import read_attrs, read_part, write_part


def main(snakemake):
    def job():
        take = snakemake.wildcards.take
        g = f"/takes/{take}"
        raw = read_part(snakemake.input.part)
        xyz, report = repair_range(
            raw[f"{g}/raw/xyz"],
            dict(snakemake.params.repair),
            source=f"{snakemake.wildcards.subject}/{take}",
        )
        filled = report.pop("filled")
        spikes = report.pop("spikes")
        logging.info("%s: %s", take, report)
        write_part(
            snakemake.output.part,
            {
                f"{g}/range/xyz": xyz.astype(np.float32),
                f"{g}/range/color": raw[f"{g}/raw/color"],
                f"{g}/range/spikes": spikes,
                f"{g}/range/filled": filled,
                f"{g}/landmarks": raw[f"{g}/landmarks"],
            },
            attrs={g: read_attrs(snakemake.input.part, g) | {"repair": report}},
        )
        write_json(snakemake.output.report, report)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
