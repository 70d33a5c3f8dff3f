"""Where command outputs go: ``--out`` checked before any work, one run folder per run, ``run.json`` in each.

A run folder is ``OUT/<UTC start>-<label>`` (``-2``, ``-3``… when a run in the same second took the name).
Its ``run.json`` records the command, the preset, the planners, the samples, the assessment, the seed, the
software versions and ``status``: ``running`` while it runs, then ``complete`` — or ``interrupted``
(Ctrl-C) / ``failed`` when it stops early; a folder left empty by an early stop is removed. Either way one line on
stderr says what was kept. Every writing command keeps this contract (tests/test_cli_contract.py); ``reproduce``
writes its own ``run.json`` (:mod:`safelane.experiments.reproduce`) with the same keys.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import os
import shlex
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError


def check_out_dir(out: Path, option: str = "--out") -> Path:
    """Create ``out`` (and parents) and prove it is writable, before any work; :class:`InputError` naming
    ``option``, the value and why otherwise."""
    out = Path(out).expanduser()
    if out.exists() and not out.is_dir():
        raise InputError(f"{option} {str(out)!r} is a file; expected a folder (it is created if missing)", option)
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".safelane-write-test-"):
            pass
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise InputError(f"{option} {str(out)!r} is not a writable folder: {reason}", option) from exc
    return out


def new_run_dir(base: Path, label: str, now: dt.datetime | None = None) -> Path:
    """A fresh folder ``base/<UTC timestamp>-<label>``."""
    now = now or dt.datetime.now(dt.timezone.utc)
    stem = f"{now:%Y%m%dT%H%M%SZ}-{label}"
    for k in range(1, 1000):
        path = base / (stem if k == 1 else f"{stem}-{k}")
        try:
            path.mkdir(parents=True)
        except FileExistsError:
            continue
        return path
    raise InputError(f"could not create a run folder under {base}", "--out")


#: The arguments the ``safelane`` command was invoked with (set by ``SafelaneGroup``; ``sys.argv`` otherwise).
invoked_args: list[str] | None = None


def command_line() -> str:
    """The command as typed (``safelane ...``)."""
    args = sys.argv[1:] if invoked_args is None else invoked_args
    return "safelane " + shlex.join(args) if args else "safelane"


def write_run_json(run_dir: Path, info: dict) -> Path:
    path = Path(run_dir) / "run.json"
    path.write_text(json.dumps(info, indent=2, default=str) + "\n", encoding="utf-8")
    return path


def preset_record(preset) -> dict | None:
    """What ``run.json`` stores of a preset: name, source file and every value."""
    if preset is None:
        return None
    return {
        "name": preset.name,
        "source": getattr(preset, "source", None),
        "params": preset.params.model_dump(),
        "sim": preset.sim.model_dump(),
        "planner": dict(preset.planner),
        "network": getattr(preset, "network", None),
    }


@contextlib.contextmanager
def run_folder(out: Path, label: str, info: dict) -> Iterator[tuple[Path, dict]]:
    """Create the run folder, write ``run.json`` (status ``running``) and yield ``(folder, info)``; the caller
    may add to ``info``. On exit ``run.json`` is rewritten with the final status; a folder that holds nothing
    but ``run.json`` after an early stop is removed."""
    from ..experiments.reproduce import software_versions

    run_dir = new_run_dir(out, label)
    started = dt.datetime.now(dt.timezone.utc)
    info = {"run_id": run_dir.name, "command": command_line(), **info, "started_utc": f"{started:%Y-%m-%d %H:%M:%S}",
            "status": "running", "versions": software_versions()}
    write_run_json(run_dir, info)
    status = "failed"
    try:
        yield run_dir, info
        status = "complete"
    except KeyboardInterrupt:
        status = "interrupted"
        raise
    finally:
        info["status"] = status
        info["finished_utc"] = f"{dt.datetime.now(dt.timezone.utc):%Y-%m-%d %H:%M:%S}"
        kept = sorted(p.name for p in run_dir.iterdir() if p.name != "run.json")
        if status != "complete" and not kept:
            with contextlib.suppress(OSError):
                (run_dir / "run.json").unlink()
                os.rmdir(run_dir)
            say(f"{status}: nothing was written yet; removed the run folder {run_dir}")
        else:
            write_run_json(run_dir, info)
            if status != "complete":
                say(f"{status}: kept {', '.join(kept)} in {run_dir} (run.json: status {status!r})")


def say(message: str) -> None:
    """One line on stderr (stdout stays for a command's result)."""
    print(message, file=sys.stderr, flush=True)


def outcome_table(title: str, table, rows, unit: str = "scenario"):
    """A Rich table of outcome counts and rates with 95 % Wilson intervals (``rows``: ``(label, column)``), then the
    mean completion time and the hesitate/abort steps per ``unit`` — the summary ``simulate`` and ``sumo`` print."""
    from rich.table import Table

    from ..sim import wilson_interval

    n = len(table)
    t = Table(title=title)
    for col, justify in (("outcome", "left"), ("count", "right"), ("rate", "right"), ("95 % Wilson interval", "right")):
        t.add_column(col, justify=justify)
    for label, col in rows:
        k = int(table[col].sum())
        lo, hi = wilson_interval(k, n)
        t.add_row(label, str(k), f"{k / n:.4f}", f"[{float(lo):.4f}, {float(hi):.4f}]")
    done = table["completion_time_s"].dropna()
    t.add_section()
    t.add_row("mean completion time", str(len(done)), f"{done.mean():.2f} s" if len(done) else "-", "")
    for label, col in ((f"hesitate steps / {unit}", "n_hesitate"), (f"abort steps / {unit}", "n_abort")):
        t.add_row(label, str(int(table[col].sum())), f"{table[col].mean():.2f}", "")
    return t

