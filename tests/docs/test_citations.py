"""Docstrings and comments cite files inside the repository: every ``docs/<name>.md §n`` names an
existing file and one of its section headings, and no citation points at notes outside it."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SOURCES = [p for pattern in ("*.py", "*.cl", "*.sh", "*.toml") for p in ROOT.rglob(pattern)
           if not {".venv", ".git", "out"} & set(p.relative_to(ROOT).parts)] + [ROOT / "README.md"]
CITATION = re.compile(r"docs/([\w-]+\.md) §(\d+(?:\.\d+)?[a-z]?)(?:-(\d+(?:\.\d+)?[a-z]?))?")
OUTSIDE = re.compile(r"shared/notes|shared/paper|notes/\w+\.md|(?<![\w/])(dept|aqm|ecosystem|DESIGN)\.md")


def citations():
    for path in SOURCES:
        for line_no, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            for m in CITATION.finditer(line):
                for section in filter(None, m.group(2, 3)):
                    yield f"{path.relative_to(ROOT)}:{line_no}", m.group(1), section


def headings(doc: Path) -> set[str]:
    return {m.group(1) for m in re.finditer(r"^#+ (\d+(?:\.\d+)?[a-z]?)\.? ", doc.read_text(), re.MULTILINE)}


def test_there_are_citations():
    assert len(list(citations())) > 30


@pytest.mark.parametrize("where, doc, section", list(citations()))
def test_citation_names_a_section_of_a_repository_doc(where, doc, section):
    path = ROOT / "docs" / doc
    assert path.is_file(), f"{where}: docs/{doc} does not exist"
    assert section in headings(path), f"{where}: docs/{doc} has no section {section}"


def test_nothing_cites_notes_outside_the_repository():
    found = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}" for p in SOURCES if p != Path(__file__).resolve()
             for i, line in enumerate(p.read_text(errors="replace").splitlines(), 1) if OUTSIDE.search(line)]
    assert not found, "\n".join(found)
