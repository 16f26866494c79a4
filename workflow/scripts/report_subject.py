"""Write results/{subject}/report.html: one self-contained page (scan2morph.report.html)."""

import json
from pathlib import Path

from scan2morph.jobs import run_job
from scan2morph.report import ReportFigure, read_caption, stage_timings, write_subject_report


def main(snakemake):
    def job():
        inp, p, subject = snakemake.input, snakemake.params, snakemake.wildcards.subject
        captions = {Path(c).stem: read_caption(c) for c in inp.captions}
        figures = [
            ReportFigure(Path(f), captions.get(Path(f).stem, Path(f).stem.replace("_", " ")))
            for f in inp.figures
        ]
        accuracy = json.loads(Path(inp.accuracy[0]).read_text()) if inp.accuracy else None
        write_subject_report(
            snakemake.output[0],
            inp.store,
            figures=figures,
            accuracy=accuracy,
            timings=stage_timings(p.benchmarks, subject, p.stage_order),
            takes=p.takes,
            n_coordinates=p.report["coordinates"],
            thumbnail_px=p.report["thumbnail_px"],
        )

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
