"""``report.md`` as HTML: the report's own Markdown (headings, paragraphs, pipe tables, lists,
images, bold and code spans) turned into HTML, so the page shows every table with exactly the
Markdown report's numbers. Tables get the ``sortable`` class. Each cell of a right-aligned
(numeric) column carries the number it starts with (``data-v``) for sorting, so ``59.40``,
``**59.40**``, ``[1.0, 2.0]`` and ``3: 50.00/0.00`` sort by their first number and a dash sorts
last; left-aligned columns (names) sort by their text, whatever digits a name holds."""

from __future__ import annotations

import html
import re

__all__ = ["markdown_to_html", "sort_value", "slug", "scroll_box"]

_NUMBER = re.compile(r"[-+−]?\d[\d,]*(?:\.\d+)?(?:[eE][-+]?\d+)?")


def slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"


def scroll_box(table: str) -> str:
    """A table inside a box that scrolls sideways when the table is wider than the page."""
    return f'<div class="tablewrap">{table}</div>'


def sort_value(cell: str) -> str:
    """The first number in a cell's text (``""`` when it has none)."""
    m = _NUMBER.search(cell.replace("**", ""))
    if m is None:
        return ""
    return m.group(0).replace(",", "").replace("−", "-")


def _inline(text: str) -> str:
    out = html.escape(text, quote=False)
    out = re.sub(r"`([^`]*)`", r"<code>\1</code>", out)  # an empty span still pairs its two backticks
    out = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", out)
    return out


def _cells(line: str) -> list[str]:
    """The cells of a table row; ``\\|`` is a ``|`` inside a cell (:func:`aw_eval.report.fmt.md_table`)."""
    inner = line.strip().removeprefix("|").removesuffix("|")
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", inner)]


def _table(lines: list[str]) -> str:
    header, align = _cells(lines[0]), _cells(lines[1])
    right = [a.endswith(":") for a in align]
    th = "".join(f'<th class="{"r" if r else "l"}">{_inline(h)}</th>' for h, r in zip(header, right, strict=True))
    rows = []
    for line in lines[2:]:
        tds = "".join(
            f'<td class="r" data-v="{sort_value(c)}">{_inline(c)}</td>' if r else f'<td class="l">{_inline(c)}</td>'
            for c, r in zip(_cells(line), right, strict=True)
        )
        rows.append(f"<tr>{tds}</tr>")
    return scroll_box(f'<table class="sortable"><thead><tr>{th}</tr></thead><tbody>{"".join(rows)}</tbody></table>')


def _list(lines: list[str]) -> str:
    """Two-level bullet list (``- `` and ``  - ``)."""
    out, open_inner = ["<ul>"], False
    for line in lines:
        inner = line.startswith("  ")
        if inner and not open_inner:
            out[-1] = out[-1].removesuffix("</li>")
            out.append("<ul>")
            open_inner = True
        elif not inner and open_inner:
            out.append("</ul></li>")
            open_inner = False
        out.append(f"<li>{_inline(line.strip()[2:])}</li>")
    if open_inner:
        out.append("</ul></li>")
    out.append("</ul>")
    return "".join(out)


def _block(block: str) -> str:
    lines = block.split("\n")
    first = lines[0]
    m = re.match(r"(#{1,4}) (.*)", first)
    if m and len(lines) == 1:
        level, text = len(m.group(1)), m.group(2)
        return f'<h{level} id="{slug(text)}">{_inline(text)}</h{level}>'
    if first.startswith("|") and len(lines) >= 2 and set(lines[1].replace("|", "").strip()) <= set("-: "):
        return _table(lines)
    m = re.fullmatch(r"!\[([^\]]*)\]\(([^)]+)\)", block.strip())
    if m:
        alt, src = html.escape(m.group(1)), html.escape(m.group(2))
        return f'<figure><img src="{src}" alt="{alt}" loading="lazy"><figcaption>{alt}</figcaption></figure>'
    if first.startswith("- "):
        return _list(lines)
    return f"<p>{_inline(' '.join(lines))}</p>"


def markdown_to_html(text: str) -> str:
    """HTML of the report's Markdown (blocks separated by blank lines)."""
    blocks = [b.strip("\n") for b in re.split(r"\n\s*\n", text) if b.strip()]
    return "\n".join(_block(b) for b in blocks)
