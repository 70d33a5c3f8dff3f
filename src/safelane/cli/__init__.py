"""The ``safelane`` command: one Typer app, one module per subcommand.

One error path for every command (:class:`SafelaneGroup`): a bad input — an option value, a config or preset
file, an ``--out`` folder — prints one line ``Error: ...`` naming the option or file (and line), the value and
what is allowed, and exits with status 2; any other failure prints one line and exits with status 1. No
traceback unless ``safelane --debug ...`` (or ``SAFELANE_DEBUG=1``). Ctrl-C exits with status 130.
"""

from __future__ import annotations

import os

import typer
from typer.core import TyperGroup

#: Exceptions that mean "the user gave something invalid": exit status 2, like Click's usage errors.
_USAGE_ERRORS = (ValueError, FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError)


class SafelaneGroup(TyperGroup):
    """Turns exceptions from a subcommand into one-line messages (see the module docstring)."""

    def invoke(self, ctx: typer.Context):
        try:
            return super().invoke(ctx)
        except typer.BadParameter as exc:
            # Commands turn input errors into BadParameter (naming the option); --debug shows where they arose.
            if _debug(ctx) and exc.__cause__ is not None:
                raise exc.__cause__ from exc
            raise
        except (typer.TyperException, typer.Exit, typer.Abort, KeyboardInterrupt):
            raise
        except Exception as exc:
            if _debug(ctx):
                raise
            from ..errors import one_line

            message = one_line(str(exc)) or type(exc).__name__
            if isinstance(exc, _USAGE_ERRORS):
                # No usage block: the one line says what was wrong and what is allowed.
                raise typer.BadParameter(message) from None
            typer.echo(f"Error: {type(exc).__name__}: {message} (run 'safelane --debug ...' for the traceback)",
                       err=True)
            raise typer.Exit(code=1) from None


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
    from . import reproduce as _reproduce  # noqa: F401
    from . import simulate as _simulate  # noqa: F401
    from . import sumo as _sumo  # noqa: F401
    from . import train as _train  # noqa: F401


_register()
