"""Reports: the per-subject HTML page, provenance, the cohort summary and parameter sweep summaries.

The last step of the data flow (io -> scan -> template -> align -> motion -> morph/modal ->
store/render/report): it reads stores, figures and accuracy files and writes reports.
"""

from scan2morph.report.cohort import (
    SubjectSummary,
    cohort_table,
    motion_rms,
    plot_cohort,
    subject_summary,
    write_cohort_summary,
)
from scan2morph.report.html import (
    ReportPage,
    clear_stale,
    mark_stale,
    subject_report_html,
    write_subject_report,
)
from scan2morph.report.provenance import software_versions, stage_timings, store_provenance
from scan2morph.report.sections import (
    ReportFigure,
    image_uri,
    read_caption,
    report_figures,
    thumbnail_jpeg,
)
from scan2morph.report.sweep import plot_sweep, sweep_summary, write_sweep_summary

__all__ = [
    "ReportFigure",
    "SubjectSummary",
    "clear_stale",
    "cohort_table",
    "image_uri",
    "mark_stale",
    "motion_rms",
    "plot_cohort",
    "plot_sweep",
    "read_caption",
    "report_figures",
    "software_versions",
    "stage_timings",
    "store_provenance",
    "subject_report_html",
    "subject_summary",
    "sweep_summary",
    "thumbnail_jpeg",
    "write_cohort_summary",
    "write_subject_report",
    "ReportPage",
    "write_sweep_summary",
]
