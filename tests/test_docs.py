"""The documentation's cross-references resolve: every relative Markdown link of README.md and
docs/ names a file that exists and, with ``#anchor``, a heading of that file (GitHub's anchors);
every section the code, configs, scripts and docs cite by name (``docs/training_log.md, "The
slip-target loop's creep cap"``) is a heading or a bold paragraph lead of the file cited.
Moving a section between files without following its references fails here."""

from __future__ import annotations

import functools
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
CITING = ("wsp_env", "baselines", "scripts", "configs", "tests", "agents", "docs")

LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
# a doc named, then (after backticks, a comma, a colon, a space or a line break) a quoted name
CITED = re.compile(r"(\w+\.md)\)?`{0,2}[,:]?\s+(?:\w+\s+)?[\"“*]{1,2}([^\"”*\n]{3,100})[\"”*]")
HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*$", re.M)
BOLD_LEAD = re.compile(r"^\s*(?:[-*]\s+)?\*\*(.+?)\*\*", re.M)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _plain(text: str) -> str:
    return re.sub(r"[`*]", "", text).strip()


@functools.cache
def sections(path: Path) -> tuple[frozenset[str], tuple[str, ...]]:
    """A Markdown file's anchors and its section names (headings and bold paragraph leads),
    read once a file (the citations ask for the same few files many times; kept, so frozen)."""
    text = path.read_text(encoding="utf-8")
    text = re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)  # code blocks hold no headings
    headings = HEADING.findall(text)
    names = [_plain(h) for h in headings] + [_plain(b) for b in BOLD_LEAD.findall(text)]
    return frozenset(slug(h) for h in headings), tuple(names)


def _doc(name: str) -> Path | None:
    hits = [p for p in DOCS if p.name == name]
    return hits[0] if len(hits) == 1 else None


def _broken_links() -> list[str]:
    broken = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        text = re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)
        for target in LINK.findall(text):
            if re.match(r"[a-z]+:", target):  # http(s), mailto: not checked here
                continue
            path, _, anchor = target.partition("#")
            file = (doc.parent / path).resolve() if path else doc
            if not file.exists():
                broken.append(f"{doc.relative_to(ROOT)}: {target}: no such file")
            elif anchor and file.suffix == ".md" and anchor not in sections(file)[0]:
                broken.append(f"{doc.relative_to(ROOT)}: {target}: no such heading")
    return broken


def _citing_files() -> list[Path]:
    files = [ROOT / "README.md"]
    for top in CITING:
        for ext in ("*.py", "*.md", "*.yaml"):
            files += sorted((ROOT / top).rglob(ext))
    return files


def _broken_citations() -> list[str]:
    broken = []
    for file in _citing_files():
        raw = file.read_text(encoding="utf-8")
        # a name wrapped over lines (comments, docstrings): one space per line break
        text = re.sub(r"[ \t]*\n[ \t]*(?:#[ \t]*)?", " ", raw)
        for name, cited in CITED.findall(text):
            doc = _doc(name)
            if doc is None:
                continue
            want = _plain(cited).rstrip(" .,;:")
            if not any(n.startswith(want) or want.startswith(n) for n in sections(doc)[1] if n):
                broken.append(f"{file.relative_to(ROOT)}: {name}, {cited!r}: no such section")
    return broken


def test_every_relative_link_names_a_file_and_heading_that_exist() -> None:
    assert _broken_links() == []


def test_every_section_cited_by_name_is_in_the_file_cited() -> None:
    assert _broken_citations() == []


@pytest.mark.parametrize(
    ("heading", "anchor"),
    [
        ("The slip-target loop's creep cap", "the-slip-target-loops-creep-cap"),
        ("Fine-tuning on the score: `wsp-env finetune`",
         "fine-tuning-on-the-score-wsp-env-finetune"),
        ("Results on `heldout`", "results-on-heldout"),
        ("The one-target family's room, probed (2026-11-28)",
         "the-one-target-familys-room-probed-2026-11-28"),
        ("The Régiolis under the cap", "the-régiolis-under-the-cap"),
        ("What a registered id fixes (`wsp_env/envs/tiers.py`)",
         "what-a-registered-id-fixes-wsp_envenvstierspy"),
    ],
)  # fmt: skip
def test_anchors_are_githubs(heading: str, anchor: str) -> None:
    assert slug(heading) == anchor


def test_a_moved_section_is_caught(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The checks can fail: a link to a heading that is not there, and a section cited in a
    file that does not hold it."""
    doc = tmp_path / "a.md"
    doc.write_text("# A\n\n## Kept here\n\n**A bold lead.** text\n\n[x](a.md#gone) [y](#kept-here)")
    cite = tmp_path / "c.py"
    cite.write_text('"""See a.md, "Kept here", and a.md, "A bold lead", and a.md, "Moved away"."""')
    here = sys.modules[__name__]
    monkeypatch.setattr(here, "DOCS", [doc])
    monkeypatch.setattr(here, "ROOT", tmp_path)
    monkeypatch.setattr(here, "_citing_files", lambda: [cite])
    assert _broken_links() == ["a.md: a.md#gone: no such heading"]
    assert _broken_citations() == ["c.py: a.md, 'Moved away': no such section"]
