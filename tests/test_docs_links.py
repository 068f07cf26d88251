"""The README's and docs/'s relative links lead somewhere: each file exists and each
``#anchor`` names a heading of its target (GitHub's slugs), so moving a section between
the README and docs/ cannot leave a dead link behind."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")
HEADING = re.compile(r"^#{1,6} (.+)$", re.M)
FENCE = re.compile(r"^```.*?^```", re.M | re.S)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    return {slug(h) for h in HEADING.findall(FENCE.sub("", path.read_text(encoding="utf-8")))}


def dead_links(path: Path) -> list[str]:
    dead = []
    for target in LINK.findall(FENCE.sub("", path.read_text(encoding="utf-8"))):
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        to = (path.parent / file).resolve() if file else path
        if not to.exists():
            dead.append(f"{target}: no such file")
        elif anchor and to.suffix == ".md" and anchor not in anchors(to):
            dead.append(f"{target}: no such heading in {to.name}")
    return dead


def test_slug_is_githubs():
    assert slug("The replays, issue 13's passes (moved from the README)") == \
        "the-replays-issue-13s-passes-moved-from-the-readme"
    assert slug("Live at 1x") == "live-at-1x"


def test_a_dead_link_is_found(tmp_path):
    (tmp_path / "a.md").write_text("# Here\n\n[ok](#here) [gone](#there) [file](b.md)\n", encoding="utf-8")
    assert dead_links(tmp_path / "a.md") == ["#there: no such heading in a.md", "b.md: no such file"]


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_every_relative_link_resolves(path):
    assert dead_links(path) == []
