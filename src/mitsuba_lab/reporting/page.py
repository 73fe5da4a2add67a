"""Self-contained HTML pages: the small Markdown subset the reports are written in, turned
into HTML with every image embedded as a data URI, so a page opens offline and can be
mailed or archived as one file.

A report is written twice from the same Markdown: ``summary.md`` (readable as text, images
as links to the PNGs beside it) and ``index.html`` (``write_markdown_page``).
"""
from __future__ import annotations

import base64
import html
import os
import re
from collections.abc import Iterable, Sequence

from ..images import atomic_path

STYLE = """body { font-family: sans-serif; margin: 2em; max-width: 1400px; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.85em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; }
th { background: #eee; } td:first-child, th:first-child { text-align: left; }
code { font-family: monospace; background: #f3f3f3; padding: 0 0.2em; }
img { max-width: 100%; }"""

_BOLD = re.compile(r"\*\*(.+?)\*\*")
_CODE = re.compile(r"`([^`]+)`")


def _inline(text: str) -> str:
    """Inline Markdown of one line (paragraph, heading or table cell) as HTML: escaped,
    ``**bold**`` as <strong>, backtick spans as <code> (their content literal: no bold inside).
    A lone backtick stays as written."""
    out, last = [], 0
    for m in _CODE.finditer(text):
        out.append(_BOLD.sub(r"<strong>\1</strong>", html.escape(text[last:m.start()])))
        out.append(f"<code>{html.escape(m.group(1))}</code>")
        last = m.end()
    out.append(_BOLD.sub(r"<strong>\1</strong>", html.escape(text[last:])))
    return "".join(out)


def block_marker(name: str) -> str:
    """A Markdown line that ``md_to_html`` replaces with the HTML block ``name`` (an HTML
    comment, so a Markdown reader of summary.md shows nothing)."""
    return f"<!-- block:{name} -->"


def md_to_html(text: str, embed_from: str | None = None, blocks: dict[str, str] | None = None) -> str:
    """The Markdown subset of the reports as HTML: ``#`` headings, ``|`` tables (first row the
    header, ``|---|`` rules skipped), ``![alt](file.png)`` images and paragraphs of one line;
    inline ``**bold**`` and backtick code spans in all of them.
    Images are read from the folder ``embed_from`` and embedded as data URIs (without it an
    image line stays text). A ``block_marker(name)`` line becomes ``blocks[name]``, raw HTML
    (an interactive viewer, say); a marker without a block is dropped."""
    out, table = [], []

    def flush_table():
        if table:
            rows = [r.strip().strip("|").split("|") for r in table if not set(r.strip()) <= set("|-")]
            out.append(html_table(rows[0], rows[1:], markdown=True))
            table.clear()

    for line in text.splitlines():
        if line.startswith("|"):
            table.append(line)
            continue
        flush_table()
        if line.startswith("<!-- block:") and line.endswith(" -->"):
            out.append((blocks or {}).get(line[len("<!-- block:"):-len(" -->")], ""))
        elif line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{_inline(line.lstrip('#').strip())}</h{level}>")
        elif line.startswith("![") and embed_from:
            alt, src = line[2:].split("](", 1)
            out.append(f'<p>{embedded_image(os.path.join(embed_from, src.rstrip(")")), alt)}</p>')
        elif line.strip():
            out.append(f"<p>{_inline(line)}</p>")
    flush_table()
    return "\n".join(out)


def html_table(header: Sequence, rows: Iterable[Sequence], row_classes: Sequence[str] | None = None,
               markdown: bool = False) -> str:
    """A <table> of escaped, stripped cells; ``row_classes`` gives each body row a CSS class;
    ``markdown``: cells are Markdown text, their inline formatting rendered (``**``, backticks)."""
    convert = _inline if markdown else html.escape
    cell = lambda tag, c: f"<{tag}>{convert(str(c).strip())}</{tag}>"   # noqa: E731
    body = []
    for i, row in enumerate(rows):
        css = f" class='{html.escape(row_classes[i])}'" if row_classes and row_classes[i] else ""
        body.append(f"<tr{css}>" + "".join(cell("td", c) for c in row) + "</tr>")
    return "<table><tr>" + "".join(cell("th", c) for c in header) + "</tr>" + "".join(body) + "</table>"


def embedded_image(path: str, alt: str = "") -> str:
    """An <img> whose source is the PNG file at ``path`` as a base64 data URI."""
    with open(path, "rb") as f:
        data = base64.b64encode(f.read()).decode()
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def html_page(title: str, body: str, style: str = "", script: str = "") -> str:
    """A complete HTML document: ``title`` (escaped here), the shared stylesheet plus
    ``style``, ``body`` (HTML, inserted as is) and ``script`` (JavaScript, run at the end of
    the body; it must not contain "</script")."""
    css = STYLE + ("\n" + style if style else "")
    if "</script" in script.lower():
        raise ValueError("html_page: the script contains </script, which would end it early")
    tail = f"<script>\n{script}\n</script>\n" if script else ""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>\n'
            f"<style>\n{css}\n</style></head><body>\n{body}\n{tail}</body></html>\n")


def write_text(path: str, text: str) -> str:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns ``path``."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
    return path


def write_markdown_page(folder: str, title: str, md: str, blocks: dict[str, str] | None = None,
                        style: str = "", script: str = "") -> dict[str, str]:
    """``folder/summary.md`` (``md``) and ``folder/index.html`` (the same Markdown as a
    self-contained page, images embedded from ``folder``, ``block_marker`` lines replaced by
    ``blocks``, plus ``style`` and ``script``); returns {"md": ..., "html": ...}."""
    paths = {"md": os.path.join(folder, "summary.md"), "html": os.path.join(folder, "index.html")}
    write_text(paths["md"], md + "\n")
    write_text(paths["html"], html_page(title, md_to_html(md, embed_from=folder, blocks=blocks), style, script))
    return paths
