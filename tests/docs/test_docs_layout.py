"""The reference (docs/) and the research wing (research/) stay apart (issue 62).

The reference is short and says what is true of the product: docs/results.md fits in 300 lines,
docs/*.md in 3,000, and no page narrates how the work was done (sessions, SIGSTOP pauses, clock
times, commit hashes). The research wing's notes are dated and may name commits, machines and
commands, but not sessions or pauses. The package's configs/ holds no research sweeps, the
studies live in research/studies/, and every relative link of both resolves."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted((ROOT / "docs").glob("*.md"))
NOTES = sorted((ROOT / "research").glob("*.md"))
SESSION = re.compile(r"\bsessions?\b|sigstop", re.IGNORECASE)
# A commit hash: 7-40 hex digits with at least one letter a-f and one digit.
COMMIT = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b")
# A clock time: a range (07:09-07:23), or a time after at/from/to/until, or before of/on.
CLOCK = re.compile(
    r"\b\d{1,2}:\d{2}\s*-\s*~?\d{1,2}:\d{2}\b"
    r"|\b(?:at|from|to|until|since) ~?\d{1,2}:\d{2}\b"
    r"|\b\d{1,2}:\d{2} (?:of|on)\b"
)


DOCS_LINES = 3000


def test_the_reference_is_short():
    assert len((ROOT / "docs" / "results.md").read_text().splitlines()) <= 300
    total = sum(len(page.read_text().splitlines()) for page in DOCS)
    assert total <= DOCS_LINES, f"docs/*.md: {total} lines"


@pytest.mark.parametrize("page", DOCS, ids=lambda p: p.name)
def test_a_reference_page_does_not_narrate_the_work(page):
    text = page.read_text()
    assert not SESSION.findall(text), page.name
    assert not COMMIT.findall(text), page.name
    assert not CLOCK.findall(text), page.name


def test_the_patterns_find_what_they_are_for():
    assert SESSION.search("the seventh Session of the day") and SESSION.search("paused (SIGSTOP)")
    assert not SESSION.search("a possession")
    assert COMMIT.findall("from commit 8e0ee0c and e120d85") == ["8e0ee0c", "e120d85"]
    assert not COMMIT.findall("1000000 frames, seed 10, a deadbeef value, 2026-11-28")
    assert CLOCK.search("paused 07:09-07:23") and CLOCK.search("resumed at 02:20")
    assert not CLOCK.search("| 9:12 | 12:28 | the observation slices")


def test_the_research_notes_are_dated_and_do_not_narrate_sessions():
    assert NOTES, "research/ has no notes"
    for note in NOTES:
        if note.name == "README.md":
            continue
        assert re.fullmatch(r"\d{4}-\d{2}-\d{2}-[a-z0-9-]+\.md", note.name), note.name
        assert not SESSION.findall(note.read_text()), note.name
    assert not SESSION.findall((ROOT / "research" / "README.md").read_text())


def test_research_sweeps_and_studies_are_not_in_the_product():
    sweeps = {p.name for p in (ROOT / "configs" / "sweep").glob("*.yaml")}
    assert not {name for name in sweeps if name.startswith(("critic_", "evidence"))}, sweeps
    assert not (ROOT / "benchmarks" / "studies").exists()
    assert sorted((ROOT / "research" / "studies").glob("*.py"))
    assert {p.name for p in (ROOT / "research" / "configs" / "sweep").glob("*.yaml")} >= {
        "evidence.yaml", "critic_selection.yaml"
    }


LINK = re.compile(r"\]\(([^)\s]+)\)")


def anchors(page: Path) -> set[str]:
    """A markdown page's heading anchors (GitHub's rule) and explicit `<a id>`s."""
    found = set()
    for line in page.read_text().splitlines():
        if re.match(r"#+ ", line):
            heading = line.lstrip("#").strip().lower()
            found.add(re.sub(r"[^\w\- ]", "", heading).replace(" ", "-"))
        found.update(re.findall(r'<a id="([^"]+)"', line))
    return found


@pytest.mark.parametrize(
    "page", [*DOCS, *NOTES, ROOT / "README.md"], ids=lambda p: p.relative_to(ROOT).as_posix()
)
def test_every_relative_link_resolves(page):
    # The notes link each figure and table to its files: a moved file or heading fails here.
    for target in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        resolved = (page.parent / path).resolve() if path else page
        assert resolved.exists(), f"{page.name}: {target}"
        if anchor and resolved.suffix == ".md" and resolved.parent.name in ("docs", "research"):
            assert anchor in anchors(resolved), f"{page.name}: {target}"
