"""The Ray connection of this process (docs/scale.md): connect to a cluster or start a local instance once, ship this
package to the workers, disconnect at the end of a session — shutting the instance down only if this process
started it. :mod:`safelane.parallel` dispatches jobs over it; the rules (which cluster, authentication, shipping
the code) are in its module docstring and ``docs/scale.md``.

Ray is the optional extra ``ray``, imported only here and only when asked for.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .errors import InputError

RAY_INSTALL_HINT = "the ray backend needs Ray: pip install 'safelane[ray]' (or: pip install 'ray>=2.9')"
#: This process's connection: whether it started the instance, where it is, and the remote task of the connection.
_state: dict[str, Any] = {"started": False, "address": None, "remote": None}


def import_ray():
    """The ``ray`` module, or :class:`ImportError` with the install hint."""
    try:
        import ray
    except ImportError as exc:
        raise ImportError(RAY_INSTALL_HINT) from exc
    return ray


def ray_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("ray") is not None


def ensure_ray(address: str | None = None, num_cpus: int | None = None):
    """Connect to (or start) Ray once per process and return the ``ray`` module; see the module docstring.

    ``num_cpus``: a wish for a freshly started local instance only (at least the machine's CPUs). An address where
    nothing listens is a :class:`ConnectionError` within seconds (Ray itself would retry for minutes)."""
    ray = import_ray()
    if ray.is_initialized():
        if address and _state["address"] not in (None, address):
            raise InputError(f"Ray is already connected to {_state['address']!r} in this process; cannot also "
                             f"connect to {address!r}", "ray_address")  # fmt: skip
        return ray
    import logging

    target = address or os.environ.get("RAY_ADDRESS") or None
    if target is None:
        local = _local_cluster(ray)  # started with `ray start --head` on this machine, and still there
        if local is None:
            # Our own instance: no usage statistics, no dashboard. RAY_AUTH_MODE is left to Ray and the user (for a
            # new local instance Ray's default is token authentication; docs/scale.md says why we keep it).
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            cpus = max(os.cpu_count() or 1, num_cpus or 0)
            ray.init(include_dashboard=False, num_cpus=cpus, runtime_env=_runtime_env(), logging_level=logging.WARNING)
            _state.update(started=True, address="a local instance started by this process")
            return ray
        target = local
    if not target.startswith("ray://") and target != "auto" and not _reachable(target):
        raise ConnectionError(f"no Ray cluster answers at {target!r} (start one with 'ray start --head --port=PORT')")
    _token_auth_like_ray_start()
    try:
        ray.init(address=target, runtime_env=_runtime_env(), logging_level=logging.WARNING)
    except ConnectionError as exc:
        raise ConnectionError(f"{exc} (a cluster with token authentication needs its token here: RAY_AUTH_TOKEN, "
                              "RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token; docs/scale.md)") from exc  # fmt: skip
    _state.update(started=False, address=target)
    return ray


def _token_auth_like_ray_start() -> None:
    """A driver that connects decides on token authentication as ``ray start`` does: with ``RAY_AUTH_MODE`` unset,
    token mode if a token is available (``RAY_AUTH_TOKEN``, ``RAY_AUTH_TOKEN_PATH`` or ``~/.ray/auth_token``). Ray
    2.5x's ``ray.init(address=...)`` does not, and fails against a ``ray start`` head node on the same machine."""
    if "RAY_AUTH_MODE" in os.environ:
        return
    try:
        from ray._private.authentication.authentication_token_setup import (
            maybe_enable_token_auth_if_token_available,
        )
    except ImportError:  # a Ray without token authentication
        return
    maybe_enable_token_auth_if_token_available(warn_if_disabled=False)


def _local_cluster(ray) -> str | None:
    """The address ``ray start --head`` left on this machine, if a cluster still answers there."""
    try:
        address = ray._private.utils.read_ray_address()
    except Exception:  # a private helper: if it moves, we start our own instance
        return None
    return address if address and _reachable(address) else None


def _reachable(address: str, timeout_s: float = 3.0) -> bool:
    """Whether something accepts TCP connections at ``HOST:PORT``."""
    import socket

    host, _, port = address.rpartition(":")
    try:
        with socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout_s):
            return True
    except (OSError, ValueError):
        return False


def _runtime_env() -> dict | None:
    """This safelane package as a ``py_modules`` entry (unless ``SAFELANE_RAY_SHIP=installed``)."""
    mode = os.environ.get("SAFELANE_RAY_SHIP", "package")
    if mode == "installed":
        return None
    if mode != "package":
        raise InputError(f"SAFELANE_RAY_SHIP must be 'package' or 'installed'; got {mode!r}", "SAFELANE_RAY_SHIP")
    return {"py_modules": [str(Path(__file__).resolve().parent)], "excludes": ["__pycache__", "*.pyc"]}


def started_ray() -> bool:
    """Whether this process started the Ray instance it is connected to."""
    return bool(_state["started"])


def shutdown_ray() -> None:
    """Disconnect from Ray; the instance stops with it only if this process started it (Ray's own rule)."""
    if "ray" not in __import__("sys").modules:
        return
    import ray

    if ray.is_initialized():
        ray.shutdown()
    _state.update(started=False, address=None, remote=None)


def connect_ray(address: str | None = None, num_cpus: int | None = None) -> bool:
    """:func:`ensure_ray`; ``True`` if this call opened the connection (its caller then closes it)."""
    already = import_ray().is_initialized()
    ensure_ray(address, num_cpus)
    return not already


@contextlib.contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None) -> Iterator[Any]:
    """Connect to (or start) Ray for a block; at its end disconnect — and so stop the instance if this process
    started it — only if the block connected (a connection open before the block stays open). Yields ``ray``."""
    opened = connect_ray(address, num_cpus)
    try:
        yield import_ray()
    finally:
        if opened:
            shutdown_ray()


def remote_task(fn):
    """``fn`` as a Ray task of 1 CPU, made once per connection (:func:`shutdown_ray` forgets it)."""
    ray = import_ray()
    if _state["remote"] is None:
        _state["remote"] = ray.remote(num_cpus=1)(fn)
    return _state["remote"]
