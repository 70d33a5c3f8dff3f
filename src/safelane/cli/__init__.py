"""The ``safelane`` command: one Typer app, one module per subcommand."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="safelane",
    help="Safe lane changing for connected autonomous vehicles in mixed traffic.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,  # help texts carry units in brackets ("[m/s²]"), which Rich markup would swallow
)


@app.callback()
def _main() -> None:
    """Safe lane changing for connected autonomous vehicles in mixed traffic."""


def _register() -> None:
    # Each subcommand module adds itself to `app`; imports are local so `--help` stays fast.
    from . import calibrate as _calibrate  # noqa: F401
    from . import check  # noqa: F401
    from . import falsify as _falsify  # noqa: F401
    from . import reproduce as _reproduce  # noqa: F401
    from . import simulate as _simulate  # noqa: F401
    from . import train as _train  # noqa: F401


_register()
