"""The report's building blocks and their two renderings: Markdown and one offline HTML page.

A section is a list of blocks — prose (a small Markdown subset: paragraphs, ``- `` bullets,
``**bold**``, `` `code` ``, or one fenced block), tables and Plotly figures. Markdown shows
figures as a pointer to the HTML page; the HTML page renders everything, Plotly.js inlined
once (:func:`app.plots.offline_page`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from html import escape
from pathlib import Path
from typing import Any

import plotly.graph_objects as go

from app.plots import offline_page


@dataclass(frozen=True, slots=True)
class Text:
    """Prose in the Markdown subset above."""

    markdown: str


@dataclass(frozen=True, slots=True)
class Table:
    """A table of already formatted cells; ``caption`` says what it is and where from."""

    caption: str
    columns: Sequence[str]
    rows: Sequence[Sequence[str]]


@dataclass(frozen=True, slots=True, eq=False)
class Figure:
    """An interactive figure (HTML only) with the caption both renderings show."""

    caption: str
    figure: go.Figure


Block = Text | Table | Figure


@dataclass(slots=True)
class Section:
    """One part of the report: ``verdict`` is its one-line agreement summary; ``data`` its
    figures as JSON-able values for ``report.json`` (empty: the section has none there)."""

    key: str
    title: str
    verdict: str
    blocks: list[Block] = field(default_factory=list)
    data: dict[str, Any] = field(default_factory=dict)


# --- number formatting ---------------------------------------------------------------------


def num(value: float | None, digits: int = 4) -> str:
    """``value`` to ``digits`` significant figures; ``n/a`` for missing or non-finite."""
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value:.{digits}g}"


def pct(fraction: float | None, decimals: int = 2) -> str:
    """A fraction as a percentage (``0.1041`` → ``10.41 %``)."""
    if fraction is None or not math.isfinite(fraction):
        return "n/a"
    return f"{100.0 * fraction:.{decimals}f} %"


# --- Markdown ------------------------------------------------------------------------------


def to_markdown(title: str, preamble: Sequence[Block], sections: Sequence[Section]) -> str:
    lines = [f"# {title}", ""]
    for block in preamble:
        lines += _md_block(block)
    for section in sections:
        lines += [f"## {section.title}", "", f"**Verdict:** {section.verdict}", ""]
        for block in section.blocks:
            lines += _md_block(block)
    return "\n".join(lines).rstrip() + "\n"


def table_markdown(table: Table) -> str:
    """One table as Markdown (caption, header, rows), e.g. for a terminal."""
    return "\n".join(_md_block(table)).rstrip() + "\n"


def _md_block(block: Block) -> list[str]:
    if isinstance(block, Text):
        return [block.markdown.strip(), ""]
    if isinstance(block, Figure):
        return [f"*Figure (interactive, in report.html):* {block.caption}", ""]
    head = "| " + " | ".join(_md_cell(c) for c in block.columns) + " |"
    rule = "|" + "|".join("---" for _ in block.columns) + "|"
    body = ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in block.rows]
    return [f"*{block.caption}*", "", head, rule, *body, ""]


def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


# --- HTML ----------------------------------------------------------------------------------

PAGE_CSS = """
body { font-family: system-ui, sans-serif; max-width: 1200px; margin: 2em auto; padding: 0 1em;
       color: #222; line-height: 1.45; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
caption { caption-side: top; text-align: left; font-style: italic; padding-bottom: 0.3em; }
code { background: #f3f3f3; padding: 0 0.2em; }
.verdict { background: #eef5ee; border-left: 4px solid #5a5; padding: 0.4em 0.8em; }
.figcap { font-style: italic; margin: 1.2em 0 0.2em; }
nav a { margin-right: 1em; }
"""


def write_html(
    path: Path, title: str, preamble: Sequence[Block], sections: Sequence[Section]
) -> None:
    parts: list[str | go.Figure] = [f"<h1>{escape(title)}</h1>"]
    parts.append(
        "<nav>" + "".join(f'<a href="#{s.key}">{escape(s.title)}</a>' for s in sections) + "</nav>"
    )
    for block in preamble:
        parts += _html_block(block)
    for section in sections:
        parts.append(f'<h2 id="{section.key}">{escape(section.title)}</h2>')
        parts.append(f'<p class="verdict"><b>Verdict:</b> {_inline(section.verdict)}</p>')
        for block in section.blocks:
            parts += _html_block(block)
    offline_page(title, parts, path, css=PAGE_CSS)


def _html_block(block: Block) -> list[str | go.Figure]:
    if isinstance(block, Text):
        return [_prose(block.markdown)]
    if isinstance(block, Figure):
        return [f'<p class="figcap">{_inline(block.caption)}</p>', block.figure]
    head = "".join(f"<th>{_inline(c)}</th>" for c in block.columns)
    body = "".join("<tr>" + "".join(_td(c) for c in row) + "</tr>" for row in block.rows)
    return [
        f"<table><caption>{_inline(block.caption)}</caption>"
        f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
    ]


_NUMBER = re.compile(r"^[-+−]?(\d[\d.,]*(e[-+]?\d+)?|n/a|—)( ?%|×)?$")


def _td(cell: str) -> str:
    css = ' class="num"' if _NUMBER.match(str(cell).strip()) else ""
    return f"<td{css}>{_inline(cell)}</td>"


def _prose(markdown: str) -> str:
    text = markdown.strip()
    if text.startswith("```"):
        return f"<pre>{escape(text.strip('`').strip())}</pre>"
    out: list[str] = []
    for para in re.split(r"\n\s*\n", markdown.strip()):
        lines = [ln.strip() for ln in para.splitlines() if ln.strip()]
        if lines and all(ln.startswith("- ") for ln in lines):
            out.append("<ul>" + "".join(f"<li>{_inline(ln[2:])}</li>" for ln in lines) + "</ul>")
        else:
            out.append(f"<p>{_inline(' '.join(lines))}</p>")
    return "\n".join(out)


def _inline(text: str) -> str:
    html = escape(str(text))
    html = re.sub(r"`([^`]+)`", r"<code>\1</code>", html)
    html = re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", html)
    return re.sub(r"(?<![*\w])\*([^*]+)\*(?![*\w])", r"<i>\1</i>", html)
