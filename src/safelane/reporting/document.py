"""A tiny document model rendered both as Markdown and as a self-contained HTML page.

The report is built once as a list of blocks (headings, paragraphs, bullet lists, tables, images, code) and
rendered twice, so ``report.md`` and ``report.html`` always say the same thing and no Markdown library is needed.
Inline text may use three Markdown forms, which the HTML renderer converts: ``**bold**``, ```code``` and
``[text](href)``; everything else is escaped.

Every heading gets an anchor (GitHub's slug of its text, so the Markdown links work on GitHub too) and
:meth:`Document.contents` places a table of contents linking them. In HTML each heading opens a ``<section>`` with
that id. Table cells that hold a number (``0.742``, ``+0.013``, ``12000``, ``0.742 [0.70, 0.78]``…) are
right-aligned; text cells, prose included, are left-aligned.
"""

from __future__ import annotations

import base64
import html
import re
from dataclasses import dataclass, field
from pathlib import Path

_INLINE = re.compile(r"\*\*(?P<bold>.+?)\*\*|`(?P<code>[^`]+)`|\[(?P<text>[^\]]+)\]\((?P<href>[^)\s]+)\)")

#: Widest the page's content gets, in CSS pixels (figures are drawn to be legible at this width).
CONTENT_WIDTH_PX = 1100
_NUMBER = re.compile(r"^—$|^\*{0,2}[−+-]?\d[\d,.]*(e[+-]?\d+)?( ?%)?\*{0,2}( \[[^\]]*\])?( / [−+-]?\d[\d.]*)*$")

_CSS = f"""
body {{ font-family: system-ui, sans-serif; max-width: {CONTENT_WIDTH_PX}px; margin: 2em auto; padding: 0 1em;
       color: #222; line-height: 1.45; }}
table {{ border-collapse: collapse; margin: 0.8em 0; font-size: 0.9em; }}
th, td {{ border: 1px solid #ccc; padding: 0.25em 0.55em; text-align: left; vertical-align: top; }}
td.num {{ text-align: right; white-space: nowrap; }}
th {{ background: #f3f3f3; }}
code, pre {{ background: #f6f6f6; font-size: 0.9em; }}
pre {{ padding: 0.6em; overflow-x: auto; }}
figure {{ margin: 1em 0; }}
figure img {{ max-width: 100%; height: auto; }}
figcaption {{ font-size: 0.95em; color: #444; }}
nav.toc {{ background: #f8f8f8; border: 1px solid #ddd; padding: 0.5em 1.2em; margin: 1em 0; }}
nav.toc ul {{ margin: 0.2em 0; padding-left: 1.2em; }}
nav.toc > ul {{ columns: 2; }}
nav.toc li {{ break-inside: avoid; }}
"""


@dataclass
class Document:
    """An ordered list of blocks; ``to_markdown`` and ``to_html`` render it."""

    title: str
    blocks: list[tuple] = field(default_factory=list)

    def heading(self, level: int, text: str) -> None:
        self.blocks.append(("heading", level, text))

    def contents(self, depth: int = 2, title: str = "Contents") -> None:
        """A table of contents here: every heading of level ``<= depth`` (rendered from the final document)."""
        self.blocks.append(("toc", depth, title))

    def anchors(self) -> list[tuple[int, str, str]]:
        """``(level, text, anchor)`` of every heading, in order (anchors unique, GitHub's slugs)."""
        seen: dict[str, int] = {}
        out = []
        for block in self.blocks:
            if block[0] == "heading":
                out.append((block[1], block[2], _unique(slug(block[2]), seen)))
        return out

    def paragraph(self, text: str) -> None:
        self.blocks.append(("paragraph", text))

    def bullets(self, items: list[str]) -> None:
        self.blocks.append(("bullets", list(items)))

    def table(self, header: list[str], rows: list[list]) -> None:
        """A table; cells are converted with ``str`` (format numbers before)."""
        self.blocks.append(("table", [str(h) for h in header], [[str(c) for c in row] for row in rows]))

    def image(self, path: Path, rel: str, caption: str, alt: str | None = None) -> None:
        """An image: ``rel`` is its path relative to the report (Markdown), ``path`` where to read it (HTML);
        ``alt`` its short text (default: the caption)."""
        self.blocks.append(("image", Path(path), rel, caption, alt or caption))

    def code(self, text: str) -> None:
        self.blocks.append(("code", text))

    # -- Markdown ---------------------------------------------------------------------------------------------
    def to_markdown(self) -> str:
        out = [f"# {self.title}", ""]
        anchors = self.anchors()
        for block in self.blocks:
            kind, *args = block
            if kind == "heading":
                out += [f"{'#' * (args[0] + 1)} {args[1]}", ""]
            elif kind == "toc":
                depth, title = args
                out += [f"**{title}**", ""]
                out += [f"{'  ' * (lvl - 1)}- [{_plain(text)}](#{a})" for lvl, text, a in anchors if lvl <= depth]
                out.append("")
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
                _, rel, caption, alt = args
                out += [f"![{_plain(alt)}]({rel})", "", f"*{caption}*", ""]
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
        anchors, k, open_levels = self.anchors(), 0, []
        for block in self.blocks:
            kind, *args = block
            if kind == "heading":
                while open_levels and open_levels[-1] >= args[0]:
                    open_levels.pop()
                    out.append("</section>")
                open_levels.append(args[0])
                level = min(args[0] + 1, 6)
                out.append(f'<section id="{anchors[k][2]}">')
                out.append(f"<h{level}>{inline_html(args[1])}</h{level}>")
                k += 1
            elif kind == "toc":
                out.append(_toc_html(anchors, *args))
            elif kind == "paragraph":
                out.append(f"<p>{inline_html(args[0])}</p>")
            elif kind == "bullets":
                out.append("<ul>" + "".join(f"<li>{inline_html(i)}</li>" for i in args[0]) + "</ul>")
            elif kind == "table":
                header, rows = args
                head = "".join(f"<th>{inline_html(h)}</th>" for h in header)
                body = "".join("<tr>" + "".join(_td(c) for c in row) + "</tr>" for row in rows)
                out.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")
            elif kind == "image":
                path, _, caption, alt = args
                out.append(
                    f'<figure><img src="{data_uri(path)}" alt="{html.escape(_plain(alt))}">'
                    f"<figcaption>{inline_html(caption)}</figcaption></figure>"
                )
            elif kind == "code":
                out.append(f"<pre><code>{html.escape(args[0])}</code></pre>")
        out += ["</section>"] * len(open_levels)
        out.append("</body></html>")
        return "\n".join(out) + "\n"


def is_number(text: str) -> bool:
    """A cell that holds a number (possibly bold, signed, a percentage, with an interval or ``a / b`` values)."""
    return bool(_NUMBER.match(text.strip()))


def _td(text: str) -> str:
    return f'<td class="num">{inline_html(text)}</td>' if is_number(text) else f"<td>{inline_html(text)}</td>"


def _plain(text: str) -> str:
    """``text`` without its inline Markdown (``**``, backticks, links reduced to their text)."""
    return _INLINE.sub(lambda m: m["bold"] or m["code"] or m["text"], text)


def slug(text: str) -> str:
    """GitHub's heading anchor: the plain text lower-cased, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", _plain(text).strip().lower()).replace(" ", "-")


def _unique(base: str, seen: dict[str, int]) -> str:
    n = seen.get(base, 0)
    seen[base] = n + 1
    return base if n == 0 else f"{base}-{n}"


def _toc_html(anchors: list[tuple[int, str, str]], depth: int, title: str) -> str:
    out, level = [f'<nav class="toc" aria-label="{html.escape(title)}"><strong>{html.escape(title)}</strong>'], 0
    for lvl, text, anchor in anchors:
        if lvl > depth:
            continue
        if lvl > level:
            out += ["<ul><li>"] * (lvl - level)
        else:
            out.append("</li></ul>" * (level - lvl) + "</li><li>")
        out.append(f'<a href="#{anchor}">{inline_html(_plain(text))}</a>')
        level = lvl
    out.append("</li></ul>" * level + "</nav>")
    return "".join(out)


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
