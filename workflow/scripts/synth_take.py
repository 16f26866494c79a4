"""Generate one synthetic take (range scan + color + landmarks) and its ground truth."""

from scan2morph.jobs import run_job
from scan2morph.synth import make_take, write_take


def main(snakemake):
    def job():
        w, p, out = snakemake.wildcards, snakemake.params, snakemake.output
        result = make_take(
            w.subject, p.take["label"], p.take["kind"], w.take, seed=p.seed, params=dict(p.scanner)
        )
        write_take(result, out.xyz, out.color, out.landmarks, out.truth)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
