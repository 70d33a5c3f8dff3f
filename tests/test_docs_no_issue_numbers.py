"""User-facing text says what it means, not "issue 12": a user cannot resolve the project's issue numbers.

Scanned: README.md, docs/*.md and the committed report, every string literal of the package (docstrings, help
texts, captions, messages; comments are not user-facing and are not scanned), the package's Markdown and YAML files
(the model card, presets' descriptions), and the help output of every CLI command.
"""

from __future__ import annotations

import ast
import re

import pytest
from typer.testing import CliRunner

from docs_blocks import REPO, doc_files

ISSUE = re.compile(r"\bissues?[ -]#?\d+", re.IGNORECASE)
PACKAGE = REPO / "src" / "safelane"


def _hits(text: str, where: str) -> list[str]:
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        for m in ISSUE.finditer(line):
            out.append(f"{where}:{n}: ...{line[max(0, m.start() - 40):m.end() + 20]}...")
    return out


def test_the_pattern_catches_what_it_should():
    assert ISSUE.search("since issue 12 the fit") and ISSUE.search("Issue 17: L0") and ISSUE.search("the issue-9 fixes")
    assert not ISSUE.search("an issue with 3 cells") and not ISSUE.search("tissue 12")


def test_docs_and_readme_name_no_issue_numbers():
    """README, docs/*.md and the committed report (its prose and captions come from the package's strings)."""
    report = [REPO / "docs" / "results" / name for name in ("report.md", "report.html")]
    paths = [*doc_files(), *(p for p in report if p.exists())]
    hits = [h for path in paths for h in _hits(path.read_text(encoding="utf-8"), str(path.relative_to(REPO)))]
    assert not hits, "\n".join(hits)


def test_package_strings_name_no_issue_numbers():
    hits = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                hits += _hits(node.value, f"{path.relative_to(REPO)}:{node.lineno}")
    for pattern in ("*.md", "*.yaml"):
        for path in sorted(PACKAGE.rglob(pattern)):
            hits += _hits(path.read_text(encoding="utf-8"), str(path.relative_to(REPO)))
    assert not hits, "\n".join(hits)


def _commands() -> list[list[str]]:
    import typer.main

    from safelane.cli import app

    group = typer.main.get_command(app)
    return [[], *([name] for name in sorted(group.commands))]


@pytest.mark.parametrize("command", _commands(), ids=lambda c: " ".join(c) or "safelane")
def test_cli_help_names_no_issue_numbers(command):
    from safelane.cli import app

    result = CliRunner().invoke(app, [*command, "--help"], terminal_width=200)
    assert result.exit_code == 0, result.output
    hits = _hits(result.output, "safelane " + " ".join(command) + " --help")
    assert not hits, "\n".join(hits)
