"""The documentation the console's numbers link to: ``docs/*.md`` served as HTML pages.

Every number the page draws on the net (a place's bound, a transition's liveness, an invariant,
a GSPN utilisation or throughput, J, R and C, a learner's probability) links to the section of the
documentation that defines it: :data:`DEFINITIONS` maps each kind of number to a page and a heading
there, and :func:`render_doc` serves the repository's ``docs/NAME.md`` as HTML (CommonMark, through
markdown-it-py) whose headings carry the ids those links name (GitHub's way: lower case, spaces
to ``-``, other punctuation dropped). Only the files of ``docs/`` are served, by name; a copy of
petrobot installed without its documentation answers 404 with a sentence saying so.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

__all__ = ["DEFINITIONS", "DOCS", "DocMissing", "render_doc", "slug"]

#: The repository's documentation folder.
DOCS = Path(__file__).resolve().parents[2] / "docs"

#: Kind of number → ``docs/PAGE.md#heading-id`` that defines it (checked by the unit tests: every
#: target exists).
DEFINITIONS: dict[str, str] = {
    "bound": "analysis.md#3-boundedness-is-always-decided-when-decidable",
    "liveness": "analysis.md#4-properties-on-a-finite-graph",
    "deadlock": "analysis.md#4-properties-on-a-finite-graph",
    "ends": "analysis.md#6-the-robotic-reading-roboticpy",
    "invariant": "analysis.md#5-invariants-invariantspy-and-the-questions-that-need-none-lppy",
    "gspn": "gspn.md#from-the-interpreted-net-to-the-gspn-p-timed-model",
    "measures": "gspn.md#measures-analyse",
    "j": "gspn.md#the-performance-function-j-performancepy",
    "learner": "learning.md#pursuit-estimator-scheme--the-default",
    "forced": "netfile.md#operator-optional-table-what-an-operator-may-force",
    "breakpoint": "console.md#breakpoints",
}

_NAME = re.compile(r"^[a-z][a-z0-9_]*\.md$")


class DocMissing(Exception):
    """No such page of the documentation (or none installed)."""


def slug(text: str) -> str:
    """A heading's id, as GitHub makes it: lower case, punctuation other than ``-`` and ``_``
    dropped, each space a ``-``."""
    text = text.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def render_doc(name: str) -> str:
    """The page ``docs/NAME`` as a whole HTML document, its headings with ids.

    Raises:
        DocMissing: ``name`` is not a page of ``docs/`` (only ``word.md`` names are looked up).
    """
    from markdown_it import MarkdownIt

    if not _NAME.match(name) or not (DOCS / name).is_file():
        raise DocMissing(f"no documentation page {name!r}" + ("" if DOCS.is_dir() else
                         " (this copy of petrobot was installed without its docs/ folder)"))
    md = MarkdownIt("commonmark", {"html": False}).enable("table")
    tokens = md.parse((DOCS / name).read_text(encoding="utf-8"))
    for i, token in enumerate(tokens):
        if token.type == "heading_open" and i + 1 < len(tokens):
            token.attrSet("id", slug(tokens[i + 1].content.replace("`", "")))
    body = md.renderer.render(tokens, md.options, {})
    return (f"<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(name)}</title>"
            f"<link rel=\"stylesheet\" href=\"/static/docs.css\"></head><body>{body}</body></html>")
