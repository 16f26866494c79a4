"""Read one take's files (range: xyz + color + landmarks) into an HDF5 part."""

from scan2morph.errors import InputError
from scan2morph.io import read_range_take
from scan2morph.jobs import run_job, sha256_file
from scan2morph.store import write_part


def main(snakemake):
    def job():
        row = snakemake.params.row
        take = row["take"]
        if row["modality"] != "range":
            raise InputError(
                f"{row['subject']}/{take}", f"modality {row['modality']!r} not supported"
            )
        scan = read_range_take(
            snakemake.input.xyz, snakemake.input.color, snakemake.input.landmarks
        )
        roles = ("xyz", "color", "landmarks")
        attrs = {k: row[k] for k in ("kind", "label", "modality")}
        attrs |= {f"input_sha256_{r}": sha256_file(snakemake.input[r]) for r in roles}
        g = f"/takes/{take}"
        write_part(
            snakemake.output.part,
            {
                f"{g}/raw/xyz": scan.xyz,
                f"{g}/raw/color": scan.color,
                f"{g}/landmarks": scan.landmarks,
            },
            attrs={g: attrs},
        )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
