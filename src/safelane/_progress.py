"""Progress bars, on stderr: a command's standard output stays its result (JSON, a table) for pipes and files."""

from __future__ import annotations


def track(items, description: str, total: int | None = None):
    """``items`` behind a transient progress bar on stderr (Rich)."""
    from rich.console import Console
    from rich.progress import track as rich_track

    return rich_track(items, total=total, description=description, transient=True, console=Console(stderr=True))
