"""Independent chunks of work on local processes or on a Ray cluster: one abstraction for every sweep (docs/scale.md).

``map_chunks(fn, jobs, backend, workers, ray_address)`` returns ``[fn(job) for job in jobs]`` — in job order,
whatever ran them and in whatever order they finished. A sweep whose jobs are pure functions of their arguments
(the simulator's are: its random draws are counter-based per scenario) therefore gives the same output, bit for bit,
on every backend and worker count. ``fn`` must be a module-level function of an importable module — in practice of
this package (``safelane.sim.engine._simulate_chunk``): Ray workers import it by name, and cannot import a test
module or a script's ``__main__``.

Backends (:data:`BACKENDS`):

* ``process`` — a :class:`~concurrent.futures.ProcessPoolExecutor` of ``workers`` processes on this machine;
  ``workers=1`` (the default) runs the jobs here, in this process.
* ``ray`` — one Ray task (1 CPU) per job. The cluster is ``ray_address``, else ``$RAY_ADDRESS``, else a Ray
  instance already running on this machine (``ray start --head``), else a fresh local instance started here
  (no dashboard, usage statistics off, as many CPUs as the machine or ``workers``, whichever is larger). The
  connection stays open for the next call (a start costs 3–5 s); :func:`ray_session` closes it at the end of a
  block — and shuts the instance down only if this process started it. ``workers=None``: the cluster's CPUs.

Shipping the code: whether it connects to a running cluster or starts a local instance, this module passes
``runtime_env={"py_modules": [<this safelane package>]}``, so every worker runs the driver's safelane — a snapshot
taken at connection time, whatever (if anything) is installed on the nodes or edited later in the checkout; its
dependencies (NumPy, pandas, pydantic, …) must be installed on every node, at the driver's versions for identical
numbers. ``SAFELANE_RAY_SHIP=installed`` skips the upload (the nodes' own install is used). Authentication: an
explicit ``RAY_AUTH_MODE`` is respected; otherwise a local instance keeps Ray's default (token authentication), and
a driver connecting to a cluster takes token mode when a token is available, as ``ray start`` does. See
``docs/scale.md``.

Ray is the optional extra ``ray`` (``pip install 'safelane[ray]'``), imported only when the ``ray`` backend is
used: ``import safelane`` never imports it.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from .errors import InputError
from .ray_cluster import (  # noqa: F401  (re-exported: the Ray connection's public names)
    RAY_INSTALL_HINT,
    connect_ray,
    ensure_ray,
    import_ray,
    ray_available,
    ray_session,
    remote_task,
    shutdown_ray,
    started_ray,
)

#: The backends :func:`map_chunks` knows.
BACKENDS = ("process", "ray")
#: How often a run with a progress channel drains it [s].
POLL_S = 0.2


@dataclass(frozen=True)
class Backend:
    """Where a sweep's chunks run: ``name`` (:data:`BACKENDS`), ``workers`` (``None``: 1 process, or every CPU of
    the Ray cluster) and, for Ray, ``ray_address``. Accepted wherever a ``workers`` count is (``as_backend``)."""

    name: str = "process"
    workers: int | None = None
    ray_address: str | None = None

    def __post_init__(self) -> None:
        check_backend_args(self.name, self.workers, self.ray_address)

    def parallelism(self) -> int:
        """How many chunks to cut a job into: ``workers``, or 1 process, or the Ray cluster's CPUs (connects)."""
        if self.workers is not None:
            return self.workers
        if self.name == "process":
            return 1
        ray = ensure_ray(self.ray_address)
        return max(1, int(ray.cluster_resources().get("CPU", 1)))

    @property
    def in_process(self) -> bool:
        """Whether the jobs run in this process (the process backend with one worker)."""
        return self.name == "process" and (self.workers or 1) == 1

    def cli_args(self) -> list[str]:
        """The command-line options that select this backend (empty for the default)."""
        out = [] if self.name == "process" else ["--backend", self.name]
        out += ["--workers", str(self.workers)] if self.workers not in (None, 1) else []
        return out + (["--ray-address", self.ray_address] if self.ray_address else [])

    def record(self) -> dict:
        """For ``run.json``."""
        return {"backend": self.name, "workers": self.workers, "ray_address": self.ray_address}


def check_backend_args(name: str, workers: int | None = None, ray_address: str | None = None) -> None:
    """:class:`~safelane.errors.InputError` naming the argument, the value and what is allowed."""
    if name not in BACKENDS:
        raise InputError(f"backend must be one of {', '.join(BACKENDS)}; got {name!r}", "backend")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise InputError(f"workers must be an integer >= 1 (or None); got {workers!r}", "workers")
    if ray_address is not None:
        if name != "ray":
            raise InputError(f"ray_address {ray_address!r} is given but the backend is {name!r}; use backend 'ray'",
                             "ray_address")  # fmt: skip
        if not isinstance(ray_address, str) or not ray_address.strip():
            raise InputError(f"ray_address must be 'HOST:PORT', 'auto' or 'ray://HOST:PORT'; got {ray_address!r}",
                             "ray_address")  # fmt: skip


def as_backend(workers: int | Backend | None = 1) -> Backend:
    """A :class:`Backend` from a ``workers`` argument: a count means that many local processes."""
    if isinstance(workers, Backend):
        return workers
    return Backend("process", 1 if workers is None else workers)


def map_chunks(
    fn: Callable,
    jobs: Sequence,
    backend: str | Backend = "process",
    workers: int | None = None,
    ray_address: str | None = None,
    progress: Callable[[Any], None] | None = None,
) -> list:
    """``[fn(job) for job in jobs]``, computed on ``backend``; results in job order (see the module docstring).

    ``backend``: a name of :data:`BACKENDS` (with ``workers`` and ``ray_address``) or a :class:`Backend`.
    ``progress``: messages from running jobs. With it, ``fn`` is called as ``fn(job, channel)`` and each
    ``channel.put(message)`` reaches ``progress(message)`` here, in this process, in the order they arrive
    (polled every :data:`POLL_S` seconds; at once when the jobs run in this process). A job's exception is raised
    here (the first in job order, as the cause Ray reports for the ``ray`` backend); the jobs not yet started are
    cancelled.
    """
    be = backend if isinstance(backend, Backend) else Backend(backend, workers, ray_address)
    jobs = list(jobs)
    if not jobs:
        return []
    if be.name == "ray":
        return _map_ray(fn, jobs, be, progress)
    if be.in_process or len(jobs) == 1:
        channel = None if progress is None else _Direct(progress)
        return [fn(job) if channel is None else fn(job, channel) for job in jobs]
    return _map_process(fn, jobs, min(be.parallelism(), len(jobs)), progress)


class _Direct:
    """A channel for jobs that run here: ``put`` is the progress callback itself."""

    def __init__(self, sink: Callable[[Any], None]):
        self.put = sink


def _map_process(fn, jobs: list, workers: int, progress) -> list:
    from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait

    with contextlib.ExitStack() as stack:
        channel = None
        if progress is not None:
            import multiprocessing

            channel = stack.enter_context(multiprocessing.Manager()).Queue()
        pool = stack.enter_context(ProcessPoolExecutor(max_workers=workers))
        try:
            futures = [pool.submit(fn, job) if channel is None else pool.submit(fn, job, channel) for job in jobs]
            while True:
                done, pending = wait(futures, timeout=POLL_S if channel is not None else None,
                                     return_when=FIRST_EXCEPTION)  # fmt: skip
                if channel is not None:
                    _drain(channel, progress)
                if not pending or any(f.exception() is not None for f in done):
                    break
            return [f.result() for f in futures]  # the first failed job, in job order, raises
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _drain(channel, progress) -> None:
    import queue

    while True:
        try:
            message = channel.get_nowait()
        except queue.Empty:
            return
        except Exception as exc:  # ray.util.queue.Empty is not a queue.Empty
            if type(exc).__name__ == "Empty":
                return
            raise
        progress(message)


@contextlib.contextmanager
def backend_session(backend: Backend) -> Iterator[Backend]:
    """:func:`ray_session` for a Ray backend; nothing for the process backend."""
    if backend.name != "ray":
        yield backend
        return
    with ray_session(backend.ray_address, backend.workers):
        yield backend


def _run_job(fn, job, channel=None):
    """The Ray task: ``fn(job)`` (or ``fn(job, channel)``). It lives here so that workers import it by name."""
    return fn(job) if channel is None else fn(job, channel)


def _map_ray(fn, jobs: list, be: Backend, progress) -> list:
    ray = ensure_ray(be.ray_address, be.workers)
    remote = remote_task(_run_job)
    channel = None
    if progress is not None:
        from ray.util.queue import Queue

        channel = Queue(actor_options={"num_cpus": 0})
    refs = [remote.remote(fn, job) if channel is None else remote.remote(fn, job, channel) for job in jobs]
    index = {ref: k for k, ref in enumerate(refs)}
    pending = list(refs)
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=POLL_S if channel else None)
            if channel is not None:
                _drain(channel, progress)
            for ref in ready:
                try:
                    ray.get(ref)
                except ray.exceptions.RayTaskError:
                    # Stop the jobs after this one; the first failure in job order is raised below.
                    for later in pending:
                        if index[later] > index[ref]:
                            ray.cancel(later)
                    pending = [p for p in pending if index[p] < index[ref]]
                    _consume(ray, refs[index[ref] + 1 :])
                    for first in refs[: index[ref] + 1]:
                        ray.get(first)
        if channel is not None:
            _drain(channel, progress)
        return ray.get(refs)
    except ray.exceptions.RayTaskError as exc:
        cause = getattr(exc, "cause", None)
        if isinstance(cause, BaseException):
            raise cause from exc
        raise
    except BaseException:
        for ref in pending:
            ray.cancel(ref)
        raise
    finally:
        if channel is not None:
            with contextlib.suppress(Exception):
                ray.kill(channel.actor)


def _consume(ray, refs) -> None:
    """Fetch (and drop) the results of finished jobs, so that Ray does not log their errors as unhandled."""
    ready, _ = ray.wait(list(refs), num_returns=len(refs), timeout=0) if refs else ([], [])
    for ref in ready:
        with contextlib.suppress(Exception):
            ray.get(ref)


def probe(job: tuple[float, float], channel=None) -> tuple[float, int, str]:
    """A diagnostic job: sleeps ``job[1]`` seconds and returns ``(job[0], pid, host)`` — where it ran; with a
    progress ``channel`` it also puts ``job[0]`` there. A negative value raises :class:`ValueError` (for testing a
    backend's error path)."""
    import socket

    value, sleep_s = job
    if value < 0:
        raise ValueError(f"probe: negative value {value!r}")
    time.sleep(sleep_s)
    if channel is not None:
        channel.put(value)
    return value, os.getpid(), socket.gethostname()
