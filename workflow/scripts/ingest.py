"""Read one take's files into an HDF5 part: range (xyz + color + landmarks) as they are, stereo
(left + right + calibration + landmarks) reconstructed into the left camera's range image."""

import logging

from scan2morph.errors import InputError
from scan2morph.io import read_range_take, read_stereo_take
from scan2morph.jobs import run_job, sha256_file
from scan2morph.scan import reconstruct_stereo
from scan2morph.store import write_part

ROLES = {
    "range": ("xyz", "color", "landmarks"),
    "stereo": ("left", "right", "calibration", "landmarks"),
}


def main(snakemake):
    def job():
        row, inp = snakemake.params.row, snakemake.input
        take, modality = row["take"], row["modality"]
        attrs = {k: row[k] for k in ("kind", "label", "modality")}
        if modality == "range":
            scan = read_range_take(inp.xyz, inp.color, inp.landmarks)
            xyz, color, landmarks = scan.xyz, scan.color, scan.landmarks
        elif modality == "stereo":
            pair = read_stereo_take(inp.left, inp.right, inp.calibration, inp.landmarks)
            source = f"{inp.left}, {inp.right}"
            xyz, report = reconstruct_stereo(
                pair.left, pair.right, pair.calib, dict(snakemake.params.stereo), source=source
            )
            logging.info("%s: stereo %s", take, report)
            xyz, color, landmarks = xyz, pair.left, pair.landmarks
            attrs["stereo"] = report
        else:
            raise InputError(f"{row['subject']}/{take}", f"modality {modality!r} not supported")
        attrs |= {f"input_sha256_{r}": sha256_file(inp[r]) for r in ROLES[modality]}
        g = f"/takes/{take}"
        write_part(
            snakemake.output.part,
            {f"{g}/raw/xyz": xyz, f"{g}/raw/color": color, f"{g}/landmarks": landmarks},
            attrs={g: attrs},
        )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
