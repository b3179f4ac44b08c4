"""Habits of the documentation, checked on the repository itself so they stay true.

README.md is for users: at most 400 lines, and it starts with the two set-up commands. The
design notes are numbered files in docs/, indexed by docs/README.md; code cites them as
``docs/<note>.md §n``, and every such citation names an existing note and one of its numbered
headings. No tracked file names a round of work, an issue number or a date of measurement: a note
states what the code does now, and the history of how it got there is in git.
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
MAX_README_LINES = 400

# Not checked for history words: this package (its patterns name what they forbid), and shipped
# third-party data that carries its own source and licence (the Khronos sample model and its
# README; the ModelFest thresholds).
EXCLUDED = ("tests/house/", "tests/scene/khronos/", "tests/aqm/data/")


def tracked_files() -> list[Path]:
    """The repository's text files: ``git ls-files``, or a walk of the tree outside a checkout."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
        names = [n for n in out.decode().split("\0") if n]
    except (OSError, subprocess.CalledProcessError):
        skip = {".git", ".venv", "out", "__pycache__", ".pytest_cache", ".ruff_cache"}
        names = [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*")
                 if p.is_file() and not skip & set(p.relative_to(ROOT).parts)]
    files = []
    for name in sorted(names):
        path = ROOT / name
        if not path.is_file():  # deleted in the work tree, not yet in the index
            continue
        data = path.read_bytes()
        if b"\0" in data:  # binary: meshes, images, arrays
            continue
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            continue
        files.append(path)
    return files


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def lines_of(paths: list[Path]):
    for path in paths:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            yield f"{_rel(path)}:{number}", line


FILES = tracked_files()
CHECKED = [p for p in FILES if not _rel(p).startswith(EXCLUDED)]


# ---------------------------------------------------------------- the README

def test_readme_is_at_most_400_lines():
    n = len(README.read_text().splitlines())
    assert n <= MAX_README_LINES, f"README.md has {n} lines; design notes belong in docs/ (docs/README.md)"


def test_readme_starts_with_the_two_set_up_commands():
    head = README.read_text().splitlines()[:15]
    fences = [i for i, line in enumerate(head) if line.strip().startswith("```")]
    assert len(fences) >= 2, "README.md must open with a code block within its first 15 lines"
    block = head[fences[0] + 1:fences[1]]
    commands = [line.split("#", 1)[0].strip() for line in block]
    assert [c for c in commands if c][:2] == ["make demo", "make test"], block


# ---------------------------------------------------------------- no history in files

ORDINALS = ("first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|thirteenth|"
            "fourteenth|fifteenth|sixteenth|seventeenth|eighteenth|nineteenth|twentieth|twenty-\\w+|thirtieth")
# A round of work: an ordinal before "session" or "round", or "a round of work". A round of an
# algorithm ("for this round" of a loop) is not one.
ROUND = re.compile(rf"\b(?:{ORDINALS}|\d+(?:st|nd|rd|th))[\s-]+(?:session|round)s?\b|\brounds? of work\b", re.I)
# "session" in prose. Not an identifier (start_new_session, requests.Session) nor a quoted value
# such as pytest's scope="session".
SESSION = re.compile(r"(?<![\w\"'.])sessions?\b(?![\"'(=])", re.I)
ISSUE = re.compile(r"\b(?i:issues?|tickets?|pull requests?)\s*#?\d+|\bPR\s*#?\d+")
# A bare "#41". A CSS colour ends in ";" or a letter, a markdown heading has a space after "#".
HASH_NUMBER = re.compile(r"(?<![\w&/#])#\d{1,5}\b(?![\w;])")
DATE = re.compile(r"\b20\d\d-[01]\d-[0-3]\d\b")
# A URL may hold a date (a dated snapshot or a versioned document): it is a source, not a measurement.
URL = re.compile(r"\b[a-z][a-z0-9+.-]*://\S+")


def _hits(*patterns: re.Pattern) -> list[str]:
    found = []
    for where, line in lines_of(CHECKED):
        text = URL.sub("", line)
        if any(p.search(text) for p in patterns):
            found.append(f"{where}: {line.strip()[:140]}")
    return found


def test_the_files_are_found():
    names = {_rel(p) for p in CHECKED}
    assert {"README.md", "docs/README.md", "pipeline/config.py", "Makefile"} <= names
    assert not any(n.startswith(EXCLUDED) for n in names)


def test_no_file_names_a_round_of_work():
    found = _hits(ROUND, SESSION)
    assert not found, "a round of work belongs in git history, not in files:\n" + "\n".join(found)


def test_no_file_names_an_issue_number():
    found = _hits(ISSUE, HASH_NUMBER)
    assert not found, "say what the code does, not which issue asked for it:\n" + "\n".join(found)


def test_no_file_names_a_date_of_measurement():
    found = _hits(DATE)
    assert not found, "figures are from today's code; dates of measurement belong in git:\n" + "\n".join(found)


@pytest.mark.parametrize("line, pattern", [
    # Written in two parts, so that this file does not itself name what it forbids
    ("Re-measured 2026-12-03, ninth " + "session", DATE),
    ("(eighth " + "session, 2026-12-03)", ROUND),
    ("what this session added", SESSION),
    ("the twenty-second " + "session's README section", ROUND),
    ("Unbiased indirect light (issue " + "11, deliverable 6)", ISSUE),
    ("so #9's cost target is met", HASH_NUMBER),
])
def test_the_patterns_catch_what_they_are_for(line, pattern):
    assert pattern.search(line)


@pytest.mark.parametrize("line", [
    '@pytest.fixture(scope="session")',
    "stdout=subprocess.DEVNULL, start_new_session=True)",
    "cluster[members] = next_id + rep[join]  # unique per representative for this round",
    "color: #222; border: 1px solid #ccc;",
    "## 1. Units",
    "dask>=2024.8 and zarr>=3.1,<3.2",
])
def test_the_patterns_leave_code_alone(line):
    assert not any(p.search(URL.sub("", line)) for p in (ROUND, SESSION, ISSUE, HASH_NUMBER, DATE))


# ---------------------------------------------------------------- the design notes and their citations

NOTE_NAME = re.compile(r"^\d\d-[a-z0-9-]+\.md$")
CITATION = re.compile(r"docs/([\w.-]+\.md)(?: §(\d+(?:\.\d+)?[a-z]?)(?:-§?(\d+(?:\.\d+)?[a-z]?))?)?")
OUTSIDE = re.compile(r"shared/notes|shared/paper|notes/\w+\.md|(?<![\w/-])(dept|aqm|ecosystem|DESIGN)\.md")


def citations():
    for where, line in lines_of([p for p in FILES if not _rel(p).startswith("tests/house/")]):
        for m in CITATION.finditer(line):
            yield where, m.group(1), [s for s in m.group(2, 3) if s]


def headings(doc: Path) -> set[str]:
    return {m.group(1) for m in re.finditer(r"^#+ (\d+(?:\.\d+)?[a-z]?)\.? ", doc.read_text(), re.MULTILINE)}


def test_notes_are_numbered_and_indexed():
    notes = sorted(p.name for p in DOCS.glob("*.md") if p.name != "README.md")
    assert notes, "docs/ holds no notes"
    unnumbered = [n for n in notes if not NOTE_NAME.match(n)]
    assert not unnumbered, f"name design notes NN-name.md: {unnumbered}"
    numbers = [n[:2] for n in notes]
    assert len(set(numbers)) == len(numbers), f"two notes share a number: {notes}"
    index = (DOCS / "README.md").read_text()
    missing = [n for n in notes if f"({n})" not in index]
    assert not missing, f"docs/README.md does not list: {missing}"


def test_there_are_citations():
    assert len([c for c in citations() if c[2]]) > 30


def test_every_docs_citation_names_an_existing_note_and_section():
    wrong = []
    for where, doc, sections in citations():
        path = DOCS / doc
        if not path.is_file():
            wrong.append(f"{where}: docs/{doc} does not exist")
            continue
        have = headings(path)
        wrong += [f"{where}: docs/{doc} has no section {s}" for s in sections if s not in have]
    assert not wrong, "\n".join(wrong)


# ``README "Section"`` or ``README, "Section"``, the title possibly broken over a comment's lines
README_CITATION = re.compile(r"\bREADME,?\s+[\"“]([^\"”]{1,120})[\"”]")


def test_every_readme_citation_names_a_readme_section():
    """The README is for users, so a citation of it names one of its headings; design content is
    cited in docs/."""
    titles = [m.group(1).strip().lower() for m in re.finditer(r"^#+ (.+)$", README.read_text(), re.MULTILINE)]
    wrong = []
    for path in FILES:
        if _rel(path).startswith("tests/house/"):
            continue
        text = path.read_text()
        for m in README_CITATION.finditer(text):
            cited = re.sub(r"\s*\n\s*#?\s*", " ", m.group(1)).strip()
            if not any(cited.lower() in title for title in titles):
                wrong.append(f"{_rel(path)}:{text.count(chr(10), 0, m.start()) + 1}: README has no section \"{cited}\"")
    assert not wrong, "\n".join(wrong)


def test_nothing_cites_notes_outside_the_repository():
    found = [f"{where}: {line.strip()}" for where, line in lines_of(CHECKED) if OUTSIDE.search(line)]
    assert not found, "\n".join(found)
