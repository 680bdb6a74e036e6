"""README.md and docs/*.md: every relative link resolves, and the README stays short.

A link is ``[text](target)`` or ``![alt](target)`` outside code (fenced blocks and inline code
spans are skipped, as GitHub does not render links there). A target with a scheme (``https:``,
``mailto:``) is external and not checked. A local target must exist relative to the linking
file; a ``#fragment`` must be the GitHub slug of a heading in the target (or in the linking
file for a bare ``#fragment``), by GitHub's rules: the heading's rendered text, lower-cased,
every character that is not a letter, digit, mark, ``_``, ``-`` or space removed, spaces turned
into ``-``, and a repeated slug suffixed ``-1``, ``-2``, ...
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
MAX_README_LINES = 250


_FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
_CODE_SPAN = re.compile(r"(`+)(?:.+?)\1", re.S)
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")


def _prose_lines(text: str) -> list[str]:
    """The lines outside fenced code blocks (a fenced block's lines become empty)."""
    out, fence = [], None
    for line in text.split("\n"):
        m = _FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)[0] * len(m.group(1))
            out.append("")
        elif fence is not None:
            if m and m.group(1).startswith(fence) and not line.strip()[len(m.group(1)):].strip():
                fence = None
            out.append("")
        else:
            out.append(line)
    return out


def github_slug(heading: str) -> str:
    """GitHub's anchor for a heading's markdown source."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)      # links render as their text
    text = re.sub(r"<[^>]+>", "", text)                            # inline HTML tags vanish
    keep = []
    for ch in text.lower():
        cat = unicodedata.category(ch)
        if cat[0] in "LNM" or cat == "Pc" or ch in "- ":
            keep.append(ch)
    return "".join(keep).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in _prose_lines(path.read_text(encoding="utf-8")):
        m = _HEADING.match(line)
        if not m:
            continue
        slug = github_slug(m.group(2))
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def links(path: Path) -> list[tuple[int, str]]:
    """(line number, target) of every markdown link outside code."""
    found = []
    for number, line in enumerate(_prose_lines(path.read_text(encoding="utf-8")), start=1):
        for m in _LINK.finditer(_CODE_SPAN.sub("", line)):
            found.append((number, m.group(1)))
    return found


def _local(target: str) -> bool:
    return not re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", target)


# --- the checker itself, on known cases (GitHub's slugs as GitHub renders them) ---------------

@pytest.mark.parametrize("heading, slug", [
    ("What the suite found", "what-the-suite-found"),
    ("solnic and solnic-modern", "solnic-and-solnic-modern"),
    ("What the suite found (measured on this code; rerun with the commands below)",
     "what-the-suite-found-measured-on-this-code-rerun-with-the-commands-below"),
    ("`pulse-width` — knob `target_step` Δ", "pulse-width--knob-target_step-δ"),
    ("`linear` and `solnic`", "linear-and-solnic"),
    ("Run-directory guarantees", "run-directory-guarantees"),
    ("See [the docs](docs/x.md) now", "see-the-docs-now"),
])
def test_github_slug(heading, slug):
    assert github_slug(heading) == slug


def test_checker_finds_links_and_skips_code(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("# A\n# A\n[x](a.md#b) `[y](no.md)` ![i](img.png \"t\") [w](https://e.org/z)\n"
                    "```\n[z](fenced.md)\n# Not a heading\n```\n## Dup (1)\n", encoding="utf-8")
    assert [t for _, t in links(page)] == ["a.md#b", "img.png", "https://e.org/z"]
    assert anchors(page) == {"a", "a-1", "dup-1"}


# --- the real pages -----------------------------------------------------------------------------

def _broken(page: Path) -> list[str]:
    problems = []
    for number, target in links(page):
        if not _local(target):
            continue
        file_part, _, fragment = target.partition("#")
        dest = (page.parent / file_part).resolve() if file_part else page
        where = f"{page.relative_to(ROOT)}:{number}: {target}"
        if not dest.exists():
            problems.append(f"{where}: no such file")
            continue
        if fragment:
            if dest.suffix != ".md":
                problems.append(f"{where}: anchor into a non-markdown file")
            elif fragment not in anchors(dest):
                problems.append(f"{where}: no heading with slug {fragment!r} in {dest.name}")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    assert links(page) or page != README, "README has no links"
    assert _broken(page) == []


def test_readme_is_short():
    lines = README.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_README_LINES, f"README.md has {lines} lines (at most {MAX_README_LINES})"


def test_every_docs_page_is_linked_from_the_readme():
    linked = {(README.parent / t.partition("#")[0]).resolve() for _, t in links(README) if _local(t)}
    orphans = [p.name for p in PAGES[1:] if p.resolve() not in linked]
    assert orphans == [], f"docs pages the README does not link: {orphans}"
