"""Write results/{subject}/report.html: one self-contained page (scan2morph.report.html)."""

import json
from pathlib import Path

from scan2morph.jobs import run_job
from scan2morph.report import stage_timings
from scan2morph.report.html import write_html
from scan2morph.stages import Subject, report


def main(snakemake):
    def job():
        inp, p = snakemake.input, snakemake.params
        subject = Subject(snakemake.wildcards.subject, p.kinds, p.labels)
        data = {
            "store": inp.store,
            "figures": inp.figures,
            "captions": inp.captions,
            "accuracy": json.loads(Path(inp.accuracy[0]).read_text()) if inp.accuracy else None,
            "timings": stage_timings(p.benchmarks, subject.name, p.stage_order),
            "glb": inp.glb,
        }
        part = report.run(None, subject, data, report.Params.from_config(snakemake.config))
        write_html(snakemake.output[0], part.files["html"])

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
