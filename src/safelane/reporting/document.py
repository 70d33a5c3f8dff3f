"""A tiny document model rendered both as Markdown and as a self-contained HTML page.

The report is built once as a list of blocks (headings, paragraphs, bullet lists, tables, images, code) and
rendered twice, so ``report.md`` and ``report.html`` always say the same thing and no Markdown library is needed.
Inline text may use three Markdown forms, which the HTML renderer converts: ``**bold**``, ```code``` and
``[text](href)``; everything else is escaped.
"""

from __future__ import annotations

import base64
import html
import re
from dataclasses import dataclass, field
from pathlib import Path

_INLINE = re.compile(r"\*\*(?P<bold>.+?)\*\*|`(?P<code>[^`]+)`|\[(?P<text>[^\]]+)\]\((?P<href>[^)\s]+)\)")

_CSS = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.55em; text-align: right; }
th { background: #f3f3f3; }
td:first-child, th:first-child { text-align: left; }
code, pre { background: #f6f6f6; font-size: 0.9em; }
pre { padding: 0.6em; overflow-x: auto; }
figure { margin: 1em 0; }
figure img { max-width: 100%; }
figcaption { font-size: 0.9em; color: #555; }
"""


@dataclass
class Document:
    """An ordered list of blocks; ``to_markdown`` and ``to_html`` render it."""

    title: str
    blocks: list[tuple] = field(default_factory=list)

    def heading(self, level: int, text: str) -> None:
        self.blocks.append(("heading", level, text))

    def paragraph(self, text: str) -> None:
        self.blocks.append(("paragraph", text))

    def bullets(self, items: list[str]) -> None:
        self.blocks.append(("bullets", list(items)))

    def table(self, header: list[str], rows: list[list]) -> None:
        """A table; cells are converted with ``str`` (format numbers before)."""
        self.blocks.append(("table", [str(h) for h in header], [[str(c) for c in row] for row in rows]))

    def image(self, path: Path, rel: str, caption: str) -> None:
        """An image: ``rel`` is its path relative to the report (Markdown), ``path`` where to read it (HTML)."""
        self.blocks.append(("image", Path(path), rel, caption))

    def code(self, text: str) -> None:
        self.blocks.append(("code", text))

    # -- Markdown ---------------------------------------------------------------------------------------------
    def to_markdown(self) -> str:
        out = [f"# {self.title}", ""]
        for block in self.blocks:
            kind, *args = block
            if kind == "heading":
                out += [f"{'#' * (args[0] + 1)} {args[1]}", ""]
            elif kind == "paragraph":
                out += [args[0], ""]
            elif kind == "bullets":
                out += [f"- {item}" for item in args[0]] + [""]
            elif kind == "table":
                header, rows = args
                out.append("| " + " | ".join(_md_cell(h) for h in header) + " |")
                out.append("|" + "|".join("---" for _ in header) + "|")
                out += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
                out.append("")
            elif kind == "image":
                _, rel, caption = args
                out += [f"![{caption}]({rel})", "", f"*{caption}*", ""]
            elif kind == "code":
                out += ["```", args[0], "```", ""]
        return "\n".join(out).rstrip() + "\n"

    # -- HTML -------------------------------------------------------------------------------------------------
    def to_html(self) -> str:
        """A self-contained page: images are embedded as base64 data URIs."""
        out = [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8">',
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>",
            f"<h1>{inline_html(self.title)}</h1>",
        ]
        for block in self.blocks:
            kind, *args = block
            if kind == "heading":
                level = min(args[0] + 1, 6)
                out.append(f"<h{level}>{inline_html(args[1])}</h{level}>")
            elif kind == "paragraph":
                out.append(f"<p>{inline_html(args[0])}</p>")
            elif kind == "bullets":
                out.append("<ul>" + "".join(f"<li>{inline_html(i)}</li>" for i in args[0]) + "</ul>")
            elif kind == "table":
                header, rows = args
                head = "".join(f"<th>{inline_html(h)}</th>" for h in header)
                body = "".join("<tr>" + "".join(f"<td>{inline_html(c)}</td>" for c in row) + "</tr>" for row in rows)
                out.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
            elif kind == "image":
                path, _, caption = args
                out.append(
                    f'<figure><img src="{data_uri(path)}" alt="{html.escape(caption)}">'
                    f"<figcaption>{inline_html(caption)}</figcaption></figure>"
                )
            elif kind == "code":
                out.append(f"<pre><code>{html.escape(args[0])}</code></pre>")
        out.append("</body></html>")
        return "\n".join(out) + "\n"


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def inline_html(text: str) -> str:
    """Escape ``text`` for HTML, converting ``**bold**``, ```code``` and ``[text](href)``."""
    out, pos = [], 0
    for m in _INLINE.finditer(text):
        out.append(html.escape(text[pos : m.start()]))
        if m["bold"] is not None:
            out.append(f"<strong>{html.escape(m['bold'])}</strong>")
        elif m["code"] is not None:
            out.append(f"<code>{html.escape(m['code'])}</code>")
        else:
            out.append(f'<a href="{html.escape(m["href"])}">{html.escape(m["text"])}</a>')
        pos = m.end()
    out.append(html.escape(text[pos:]))
    return "".join(out)


def data_uri(path: Path) -> str:
    """``path`` as a base64 ``data:`` URI (PNG or SVG)."""
    mime = {".png": "image/png", ".svg": "image/svg+xml"}.get(Path(path).suffix.lower(), "application/octet-stream")
    return f"data:{mime};base64,{base64.b64encode(Path(path).read_bytes()).decode('ascii')}"
