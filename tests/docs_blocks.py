"""The fenced code blocks of README.md and docs/*.md, and the commands in them (tests/test_docs_commands.py).

A block tagged ``bash``/``sh``/``shell`` holds commands, one a line (``\\`` continues a line; ``# ...`` after
whitespace is a comment); a ``python`` block is one program. An untagged or ``text`` block is recorded output: its
lines that start with ``$ `` are the commands that produced it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHELL_LANGS = ("bash", "sh", "shell")
OUTPUT_LANGS = ("", "text")
KNOWN_LANGS = (*SHELL_LANGS, "python", *OUTPUT_LANGS)


def doc_files() -> list[Path]:
    """README.md and every docs/*.md, in a fixed order."""
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


@dataclass(frozen=True)
class Block:
    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(REPO)}:{self.line}"

    def commands(self) -> list[str]:
        """The shell commands of a shell block, or the ``$ `` lines of an output block (comments stripped,
        continuation lines joined, blanks collapsed); a Python block has none."""
        if self.lang in SHELL_LANGS:
            joined = re.sub(r"\\\n\s*", " ", self.text)
            out = []
            for raw in joined.splitlines():
                line = re.sub(r"(^|\s)#.*$", "", raw).strip()
                if line:
                    out.append(normalize(line))
            return out
        if self.lang in OUTPUT_LANGS:
            return [normalize(raw.strip()[2:]) for raw in self.text.splitlines() if raw.strip().startswith("$ ")]
        return []


def normalize(command: str) -> str:
    return " ".join(command.split())


def fenced_blocks(path: Path) -> list[Block]:
    lines = path.read_text(encoding="utf-8").split("\n")
    blocks, i = [], 0
    while i < len(lines):
        m = re.match(r"^\s*```(\S*)\s*$", lines[i])
        if m:
            start, body = i, []
            i += 1
            while i < len(lines) and not re.match(r"^\s*```\s*$", lines[i]):
                body.append(lines[i])
                i += 1
            if i == len(lines):
                raise AssertionError(f"{path.relative_to(REPO)}:{start + 1}: unclosed code fence")
            indent = len(lines[start]) - len(lines[start].lstrip())
            text = "\n".join(b[indent:] if b[:indent].isspace() else b for b in body)
            blocks.append(Block(path, start + 1, m.group(1).lower(), text))
        i += 1
    return blocks


def all_blocks() -> list[Block]:
    return [b for path in doc_files() for b in fenced_blocks(path)]
