"""``--backend``, ``--workers`` and ``--ray-address``: where a command's sweeps run (docs/scale.md).

Every command that simulates many scenarios takes the three options; :func:`resolve_backend` checks them before any
work and returns what the experiment functions take as ``workers``: a number of local processes, or a
:class:`~safelane.parallel.Backend` for Ray. A bad value (an unknown backend, ``--ray-address`` without Ray, Ray not
installed) is one line naming the option, exit status 2.
"""

from __future__ import annotations

import contextlib

import typer

from ..parallel import BACKENDS

BACKEND_HELP = f"Where simulations run: {' or '.join(BACKENDS)} (a Ray cluster; extra 'ray'; docs/scale.md)."
WORKERS_HELP = "Processes (default 1: this process), or Ray tasks per batch (default: the cluster's CPUs)."
RAY_ADDRESS_HELP = "Ray cluster HOST:PORT (default $RAY_ADDRESS, else a running local cluster, else a fresh one)."


def backend_option():
    return typer.Option("process", "--backend", help=BACKEND_HELP)


def workers_option(help: str = WORKERS_HELP):
    return typer.Option(None, "--workers", min=1, help=help)


def ray_address_option():
    return typer.Option(None, "--ray-address", help=RAY_ADDRESS_HELP)


def resolve_backend(backend: str, workers: int | None, ray_address: str | None):
    """``workers`` as the Python API takes it (an int for local processes, a ``Backend`` for Ray), or
    :class:`typer.BadParameter` naming the option."""
    from ..parallel import RAY_INSTALL_HINT, Backend, check_backend_args, ray_available

    if backend not in BACKENDS:
        raise typer.BadParameter(f"{backend!r} is not a backend; allowed: {', '.join(BACKENDS)}",
                                 param_hint="--backend")  # fmt: skip
    if ray_address is not None and backend != "ray":
        raise typer.BadParameter(f"{ray_address!r} needs --backend ray (the backend is {backend!r})",
                                 param_hint="--ray-address")  # fmt: skip
    try:
        check_backend_args(backend, workers, ray_address)
    except ValueError as exc:
        hint = {"workers": "--workers", "ray_address": "--ray-address"}.get(getattr(exc, "where", ""), "--backend")
        raise typer.BadParameter(str(exc), param_hint=hint) from exc
    if backend == "process":
        return workers or 1
    if not ray_available():
        raise typer.BadParameter(RAY_INSTALL_HINT, param_hint="--backend")
    return Backend("ray", workers, ray_address)


@contextlib.contextmanager
def session(workers):
    """One Ray connection for the whole command (a local instance we started stops at the end); nothing for
    local processes. A cluster that does not answer is one line naming ``--ray-address``, exit status 2."""
    from ..parallel import Backend, connect_ray, shutdown_ray

    if not isinstance(workers, Backend):
        yield
        return
    announce_ray(workers.ray_address)
    try:
        opened = connect_ray(workers.ray_address, workers.workers)
    except ConnectionError as exc:
        raise typer.BadParameter(str(exc), param_hint="--ray-address") from exc
    try:
        yield
    finally:
        if opened:
            shutdown_ray()


def record(workers) -> dict:
    """What ``run.json`` says about where the run ran."""
    from ..parallel import as_backend

    return as_backend(workers).record()


def announce_ray(address: str | None) -> None:
    """Say on stderr what connecting is about to do: a fresh local Ray runtime takes tens of seconds to start."""
    import os
    import sys

    from ..ray_cluster import _local_cluster, import_ray

    ray = import_ray()
    if ray.is_initialized():
        return
    target = address or os.environ.get("RAY_ADDRESS") or _local_cluster(ray)
    if target:
        message = f"connecting to the Ray cluster at {target}..."
    else:
        message = "starting a local Ray runtime (~40 s; a running cluster: --ray-address or 'ray start --head')..."
    print(message, file=sys.stderr, flush=True)
