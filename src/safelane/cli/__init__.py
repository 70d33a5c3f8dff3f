"""The ``safelane`` command: one Typer app, one module per subcommand.

One error path for every command (:class:`SafelaneGroup`): a bad input — an option value, a config or preset
file, an ``--out`` folder — prints one line ``Error: ...`` naming the option or file (and line), the value and
what is allowed, and exits with status 2; any other failure prints one line and exits with status 1. No
traceback unless ``safelane --debug ...`` (or ``SAFELANE_DEBUG=1``). Ctrl-C exits with status 130.
"""

from __future__ import annotations

import contextlib
import os
import re
import traceback
import warnings

import typer
from typer.core import TyperGroup

#: Exceptions that mean "the user gave something invalid": exit status 2, like Click's usage errors.
_USAGE_ERRORS = (ValueError, FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError)
#: Click's base of its own errors (Typer may vendor Click, so taken from ``typer.BadParameter``).
_CLICK_ERROR = next(c for c in typer.BadParameter.__mro__ if c.__name__ == "ClickException")
#: NumPy scalar reprs (``np.float64(50.0)``) in a message: shown as the plain value (``50.0``).
_NUMPY_REPR = re.compile(r"\bnp\.(?:float|int|uint|bool_|bool|str_|complex)\d*\(([^()]*)\)")


class SafelaneGroup(TyperGroup):
    """Turns exceptions from a subcommand into one-line messages (see the module docstring)."""

    def make_context(self, info_name, args, parent=None, **extra):
        if parent is None:  # the command line as given (sys.argv, or a test runner's list) for run.json
            from . import _runs

            _runs.invoked_args = list(args)
        return super().make_context(info_name, args, parent=parent, **extra)

    def invoke(self, ctx: typer.Context):
        debug = _debug(ctx)
        with _one_line_warnings(debug):
            try:
                return super().invoke(ctx)
            except typer.BadParameter as exc:
                # Commands turn input errors into BadParameter (naming the option); --debug shows where they arose.
                cause = exc.__cause__
                if isinstance(cause, OSError) and cause.strerror and exc.message == str(cause):
                    exc.message = _describe(cause)  # '[Errno 2] No such file...: PATH' -> 'PATH': No such file...
                exc.message = plain_message(exc.message)
                if exc.param is not None and "got " not in exc.message:  # Click's own checks omit the value
                    value = _given(getattr(exc.param, "opts", ()))
                    exc.message += "" if value is None else f"; got {value}"
                if exc.param_hint is None and exc.param is None:
                    exc.param_hint = _option_of(ctx, exc.__cause__)
                if debug:
                    _print_traceback(exc)
                raise
            except (_CLICK_ERROR, typer.Exit, typer.Abort):
                raise
            except KeyboardInterrupt:
                # Whatever wrote a run folder has said what it kept; this line says why the command stopped.
                typer.echo("Interrupted (Ctrl-C); exit status 130.", err=True)
                raise typer.Exit(code=130) from None
            except Exception as exc:
                message = _describe(exc)
                if debug:
                    _print_traceback(exc)
                if isinstance(exc, _USAGE_ERRORS):
                    # No usage block: the one line says what was wrong and what is allowed.
                    raise typer.BadParameter(message, param_hint=_option_of(ctx, exc)) from None
                hint = "" if debug else " (run 'safelane --debug ...' for the traceback)"
                typer.echo(f"Error: {type(exc).__name__}: {message}{hint}", err=True)
                raise typer.Exit(code=1) from None


def plain_message(text: str) -> str:
    """One line, NumPy scalars shown as plain numbers (``np.float64(50.0)`` → ``50.0``)."""
    from ..errors import one_line

    return _NUMPY_REPR.sub(r"\1", one_line(text))


def _given(opts) -> str | None:
    """The value typed after an option (its last occurrence), as typed; ``None`` if not found."""
    from . import _runs

    args, value = _runs.invoked_args or [], None
    for i, arg in enumerate(args):
        for opt in opts:
            if arg == opt and i + 1 < len(args):
                value = args[i + 1]
            elif opt.startswith("--") and arg.startswith(opt + "="):
                value = arg[len(opt) + 1 :]
    return value


def _describe(exc: BaseException) -> str:
    """The one line of an exception: an ``OSError`` as ``'FILE': reason`` (not ``[Errno 2] ...``)."""
    if isinstance(exc, OSError) and exc.strerror:
        where = f"{exc.filename!r}" + (f" -> {exc.filename2!r}" if exc.filename2 else "") if exc.filename else ""
        return plain_message(f"{where}: {exc.strerror}" if where else exc.strerror)
    return plain_message(str(exc)) or type(exc).__name__


def _option_of(ctx: typer.Context, exc: BaseException | None) -> str | None:
    """The option an exception's ``where`` (an :class:`~safelane.errors.InputError` field) names, if the command has
    one of that name (``samples`` → ``--samples``); ``where`` itself when it already is an option."""
    where = getattr(exc, "where", None)
    if not where:
        return None
    where = str(where)
    if where.startswith("-"):
        return where
    command, name = ctx.command, ctx.invoked_subcommand
    if name and hasattr(command, "get_command"):
        command = command.get_command(ctx, name) or command
    for param in command.params:
        if param.name == where.replace("-", "_") and param.param_type_name == "option":
            return max(param.opts, key=len)
    return None


def _print_traceback(exc: BaseException) -> None:
    """The full traceback (causes included) on stderr: what ``--debug`` and ``SAFELANE_DEBUG=1`` add."""
    if isinstance(exc, _CLICK_ERROR) and exc.__cause__ is not None:
        exc = exc.__cause__
    typer.echo("".join(traceback.format_exception(type(exc), exc, exc.__traceback__)).rstrip(), err=True)


@contextlib.contextmanager
def _one_line_warnings(debug: bool):
    """A warning during a command as one line ``Warning: ...`` on stderr, each text once (Python's default shows
    the file and the source line that triggered it); unchanged under ``--debug``."""
    if debug:
        yield
        return
    seen: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = plain_message(str(message))
        if text not in seen:
            seen.add(text)
            typer.echo(f"Warning: {text}", err=True)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def _debug(ctx: typer.Context) -> bool:
    return bool(ctx.params.get("debug")) or os.environ.get("SAFELANE_DEBUG", "") not in ("", "0")


app = typer.Typer(
    name="safelane",
    help="Safe lane changing for connected autonomous vehicles in mixed traffic.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,  # help texts carry units in brackets ("[m/s²]"), which Rich markup would swallow
    cls=SafelaneGroup,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"safelane {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    debug: bool = typer.Option(False, "--debug", help="Show the full traceback of an error (or SAFELANE_DEBUG=1)."),
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Safe lane changing for connected autonomous vehicles in mixed traffic."""


def _register() -> None:
    # Each subcommand module adds itself to `app`; imports are local so `--help` stays fast.
    from . import calibrate as _calibrate  # noqa: F401
    from . import check  # noqa: F401
    from . import export as _export  # noqa: F401
    from . import falsify as _falsify  # noqa: F401
    from . import replay as _replay  # noqa: F401
    from . import reproduce as _reproduce  # noqa: F401
    from . import simulate as _simulate  # noqa: F401
    from . import sumo as _sumo  # noqa: F401
    from . import traffic as _traffic  # noqa: F401
    from . import train as _train  # noqa: F401


_register()
