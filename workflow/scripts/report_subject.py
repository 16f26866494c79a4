"""Write results/{subject}/report.html: one self-contained page (scan2morph.report.html)."""

from scan2morph.jobs import run_job
from scan2morph.stages import report


def main(snakemake):
    def job():
        inp, p, subject = snakemake.input, snakemake.params, snakemake.wildcards.subject
        timings = {"benchmarks": p.benchmarks, "subject": subject, "order": p.stage_order}
        out, figures = snakemake.output[0], (inp.figures, inp.captions, inp.accuracy)
        report.run(out, inp.store, *figures, timings, p.takes, p.report, glb=inp.glb)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
