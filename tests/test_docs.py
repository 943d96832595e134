"""The documentation's links resolve, and the README stays short.

Every relative link (and image) in README.md, CHANGELOG.md, bags/README.md and docs/**/*.md names a file or
folder that exists; a link with ``#anchor`` names a heading of its target as GitHub spells the anchor (the
slug rules below). Links inside code (fenced blocks, inline backticks) are text, not links, and are not
checked. Plain pytest: no rclpy, no build needed, well under a second.
"""

from __future__ import annotations

import pathlib
import re
from collections import Counter

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: the README's length limit (issue 30): what it is, the two commands, a short tour, where to go next
README_MAX_LINES = 200

_FENCE = re.compile(r"^\s*(```|~~~)")
_INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
#: [text](target) and ![alt](target), target up to the first space or closing parenthesis
_LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
_EXTERNAL = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def doc_files() -> list[pathlib.Path]:
    """The checked pages: README.md, CHANGELOG.md, bags/README.md and every page under docs/."""
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "bags" / "README.md"]
    files += sorted((ROOT / "docs").rglob("*.md"))
    return [f for f in files if f.is_file()]


def _prose_lines(text: str) -> list[str]:
    """The lines of ``text`` outside fenced code blocks, inline code blanked out."""
    lines, fenced = [], False
    for line in text.splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(_INLINE_CODE.sub("", line))
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor of a heading's text: Markdown links reduced to their text, lower case, every
    character but letters, digits, ``_``, ``-`` and spaces dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = re.sub(r"<[^>]+>", "", text).strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: pathlib.Path) -> set[str]:
    """Every heading anchor of ``path``; repeated headings get ``-1``, ``-2``... as on GitHub."""
    seen: Counter[str] = Counter()
    out = set()
    fenced = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            continue
        m = None if fenced else _HEADING.match(line)
        if m:
            base = slug(m.group(2))
            out.add(base if seen[base] == 0 else f"{base}-{seen[base]}")
            seen[base] += 1
    return out


def links(path: pathlib.Path) -> list[str]:
    """The relative link targets of ``path`` (external URLs and mail addresses left out)."""
    found = []
    for line in _prose_lines(path.read_text(encoding="utf-8")):
        for m in _LINK.finditer(line):
            target = m.group(1)
            if not _EXTERNAL.match(target):
                found.append(target)
    return found


def broken_links(path: pathlib.Path) -> list[str]:
    """The links of ``path`` that name no existing file, or no heading of an existing Markdown file."""
    bad = []
    for target in links(path):
        name, _, anchor = target.partition("#")
        dest = (path.parent / name).resolve() if name else path
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            shown = dest.relative_to(ROOT) if dest.is_relative_to(ROOT) else dest.name
            bad.append(f"{target}: no heading #{anchor} in {shown}")
    return bad


@pytest.mark.parametrize("page", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page: pathlib.Path) -> None:
    assert broken_links(page) == []


def test_the_checked_pages_include_the_docs_tree() -> None:
    pages = {str(p.relative_to(ROOT)) for p in doc_files()}
    assert {"README.md", "bags/README.md"} <= pages
    assert any(p.startswith("docs/guide/") for p in pages)
    assert any(p.startswith("docs/reference/") for p in pages)
    assert any(p.startswith("docs/design/") for p in pages)
    assert any(p.startswith("docs/results/") for p in pages)


def test_readme_is_at_most_200_lines() -> None:
    n = len((ROOT / "README.md").read_text(encoding="utf-8").splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines, at most {README_MAX_LINES}"


def test_the_checker_sees_a_broken_link_and_anchor(tmp_path: pathlib.Path) -> None:
    (tmp_path / "a.md").write_text("# A title, with `code`!\n\n## Twice\n## Twice\n")
    page = tmp_path / "b.md"
    page.write_text("[ok](a.md#a-title-with-code) [ok](a.md#twice-1) [bad](a.md#nope) [gone](c.md)\n"
                    "`[in code](d.md)`\n```\n[fenced](e.md)\n```\n[web](https://example.org/x.md)\n")
    assert broken_links(page) == ["a.md#nope: no heading #nope in a.md", "c.md: no such file"]


@pytest.mark.integration
def test_the_executables_reference_is_what_the_executables_print(help_texts):
    """docs/reference/executables.md is every installed executable's --help: the page scripts/executables_doc.py
    writes, from the session's run of every ``--help`` (tests/conftest.py's ``help_texts``, which test_ros2cli.py
    checks too; the script's ``--check`` runs them itself)."""
    from conftest import executables_doc

    doc = executables_doc()

    def shown(package: str, args: list[str]) -> str:
        done = help_texts[" ".join(args)]
        assert done["returncode"] == 0, f"{' '.join(args)} --help: exit {done['returncode']}\n{done['stderr']}"
        return done["stdout"].rstrip()

    doc._help = shown  # what the script's _help runs, taken from the session's run
    assert doc.page() == doc.PAGE.read_text(encoding="utf-8"), \
        "docs/reference/executables.md is stale: run ./run exec python scripts/executables_doc.py"
