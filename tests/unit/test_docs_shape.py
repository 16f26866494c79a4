"""The user-facing text keeps the shape issue #31 gave it: a README a person reads in one sitting,
and a configuration whose comments and schema descriptions give meaning, unit and default only
(measurements, dates and what changed belong in docs/ and CHANGELOG.md); every path it names
and every link between its pages leads somewhere."""

from __future__ import annotations

import re

from tests.support.configs import REPO, config_schema

#: A measurement or a change: an ISO date, a commit hash, "a -> b", "Measured ...".
HISTORY = re.compile(
    r"\b20\d\d-\d\d-\d\d\b"  # a date
    r"|\b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b"  # a commit
    r"|\d\s*->\s*\d"  # a before and after
    r"|\bMeasured\b|measured (worse|better)"  # a measurement
)

#: The files a user or contributor reads for paths and links: the docs, and the comments of the
#: config, the profiles, the Makefile and pyproject.toml (CHANGELOG.md keeps history's names).
GUIDES = (
    "README.md",
    "CONTRIBUTING.md",
    "docs/*.md",
    "config/config.yaml",
    "profiles/*/config.yaml",
    "Makefile",
    "pyproject.toml",
)
#: A path in the repository, e.g. tests/workflow/test_slurm.py or docs/cluster.md.
REPO_PATH = re.compile(
    r"(?<![\w./-])((?:tests|benchmarks|tools|workflow|src|config|schemas|profiles|resources|docs)"
    r"/[\w./-]*\w)"
)
#: Paths the guides name that are not in the repository but made by `make setup` (the viewer's
#: bundle and its npm packages) or by a run (the template, the rules' benchmark files): each is
#: named by the Makefile or a rule file that makes it (checked).
MADE = (
    "benchmarks/rules",
    "benchmarks/takes",
    "benchmarks/subjects",
    "resources/template.npz",
    "tools/viewer/dist",
    "tools/viewer/node_modules",
)
#: A Markdown link to a file of the repository, with its anchor: [text](target#anchor).
LINK = re.compile(r"\]\((?!https?:)([^)#\s]*)(?:#([^)\s]+))?\)")


def _descriptions(node, path="") -> list[tuple[str, str]]:
    """Every schema ``description`` with its key path."""
    out = []
    if isinstance(node, dict):
        if isinstance(node.get("description"), str):
            out.append((path, node["description"]))
        for key, value in node.items():
            out += _descriptions(value, f"{path}.{key}")
    elif isinstance(node, list):
        for k, value in enumerate(node):
            out += _descriptions(value, f"{path}[{k}]")
    return out


def test_the_readme_is_short():
    assert len((REPO / "README.md").read_text(encoding="utf-8").splitlines()) <= 200


def test_schema_descriptions_and_config_comments_carry_no_history():
    offences = [p for p, text in _descriptions(config_schema()) if HISTORY.search(text)]
    for number, line in enumerate(
        (REPO / "config" / "config.yaml").read_text(encoding="utf-8").splitlines(), 1
    ):
        if "#" in line and HISTORY.search(line.split("#", 1)[1]):
            offences.append(f"config.yaml:{number}")
    assert not offences, offences


def test_the_history_pattern_finds_what_it_names():
    for text in (
        "before 2026-12-02",
        "0.454 -> 0.379 mm",
        "Measured on 30 takes",
        "a1b2c3d4",
        "measured worse",
    ):
        assert HISTORY.search(text), text
    for text in (
        "default 0.875, px",
        "lanczos4",
        "iBUG 58",
        "1e-12 of the largest",
        "auto: measured on the stable points",
    ):
        assert not HISTORY.search(text), text


def _guides():
    """The files of :data:`GUIDES`."""
    return [path for pattern in GUIDES for path in sorted(REPO.glob(pattern))]


def _anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to -."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_every_repository_path_the_guides_name_exists():
    """Every path exists, in a fresh clone too: the ones setup or a run makes (:data:`MADE`) are
    named by what makes them."""
    makers = "\n".join(
        p.read_text(encoding="utf-8")
        for p in [REPO / "Makefile", *sorted((REPO / "workflow" / "rules").glob("*.smk"))]
    )
    assert [m for m in MADE if m not in makers] == []
    missing = []
    for guide in _guides():
        for number, line in enumerate(guide.read_text(encoding="utf-8").splitlines(), 1):
            for match in REPO_PATH.finditer(line):
                path = match.group(1).rstrip(".")
                made = path.startswith(MADE)
                if not path.endswith("_") and not made and not (REPO / path).exists():
                    missing.append(f"{guide.relative_to(REPO)}:{number}: {path}")
    assert not missing, missing


def test_every_link_between_the_docs_reaches_its_file_and_heading():
    dead = []
    for guide in (path for path in _guides() if path.suffix == ".md"):
        for number, line in enumerate(guide.read_text(encoding="utf-8").splitlines(), 1):
            for target, anchor in LINK.findall(line):
                path = (guide.parent / target).resolve() if target else guide
                headings = []
                if path.is_file() and path.suffix == ".md":
                    text = path.read_text(encoding="utf-8")
                    headings = [_anchor(h) for h in re.findall(r"^#+ (.*)$", text, re.M)]
                if not path.exists() or (anchor and anchor not in headings):
                    dead.append(f"{guide.relative_to(REPO)}:{number}: {target}#{anchor}")
    assert not dead, dead
