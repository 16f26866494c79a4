"""Every problem of a subject's sheet rows and files at once: stop the subject (its own or its
neutral's problem) or name the takes to leave out."""

from scan2morph.jobs import run_job, write_json
from scan2morph.stages import Take, check


def main(snakemake):
    def job():
        p = snakemake.params
        subject = snakemake.wildcards.subject
        takes = [Take.from_row(row, files=p.files.get(row["take"], {})) for row in p.rows]
        report = check.check_subject(subject, takes, p.problems)
        # the files each verdict was found on: a take's job trusts it for those alone
        # (check.take_verdict)
        report["files"] = {t.take: check.input_checksums(t.files) for t in takes}
        write_json(snakemake.output[0], report)

    run_job(snakemake.log[0], job)


if __name__ == "__main__":
    main(snakemake)  # noqa: F821
