"""User-input errors: one line naming the file (and line) or the argument, the value and what is allowed.

Every entry point (the Python API, the ``safelane`` command, config and preset files) reports a bad input as
an :class:`InputError` — a :class:`ValueError`, so existing ``except ValueError`` code keeps working — whose
message is a single line. The command line prints that line and exits with status 2 (see ``safelane.cli``).
"""

from __future__ import annotations

from pydantic import ValidationError


class InputError(ValueError):
    """A bad input to safelane. ``where`` names the argument, option or file; the message is one line."""

    def __init__(self, message: str, where: str | None = None):
        super().__init__(message)
        self.where = where


def one_line(text: str) -> str:
    """Collapse whitespace (newlines included) to single spaces."""
    return " ".join(str(text).split())


def describe_validation_error(
    exc: ValidationError, source: str | None = None, prefix: str = "", allowed: list[str] | None = None
) -> str:
    """One line per pydantic error, joined by ``; ``: ``SOURCE: field 'a.b' = VALUE: what is allowed``.

    ``prefix`` is prepended to every field path (``params.`` when the model is nested in a file); ``allowed``
    lists the valid field names, shown after an unknown one."""
    parts = []
    for err in exc.errors(include_url=False):
        loc = prefix + ".".join(str(p) for p in err.get("loc", ()))
        msg = err.get("msg", "invalid")
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, ") :]
        kind = err.get("type", "")
        if kind == "extra_forbidden":
            text = f"unknown field {loc!r}" + (f" (allowed: {', '.join(allowed)})" if allowed else "")
        elif kind == "missing":
            text = f"field {loc!r} is required"
        elif loc:
            text = f"field {loc!r} = {err.get('input')!r}: {msg}"
        else:
            text = msg
        parts.append(one_line(text))
    body = "; ".join(parts) or one_line(str(exc))
    return f"{source}: {body}" if source else body
