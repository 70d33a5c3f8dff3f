"""A sweep against a Ray cluster started the way a real one is (issue 13): ``ray start --head`` on a port, then
``safelane reproduce --backend ray --ray-address 127.0.0.1:PORT``; the CSVs must equal ``--backend process``'s.

The head node runs in its own temp dir (so no other session's "running local cluster" lookup finds it) under
``ray start --block``, and is stopped by ending that one process group — never ``ray stop``, which stops every Ray
instance of the user on the machine. Needs the extra ``ray``.

    .venv/bin/python benchmarks/ray_cluster.py [--only table1] [--workers 2] [--cpus 2]
"""

from __future__ import annotations

import argparse
import filecmp
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(port: int, timeout_s: float = 90.0) -> float:
    start = time.perf_counter()
    while time.perf_counter() - start < timeout_s:
        with socket.socket() as s:
            s.settimeout(1.0)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return time.perf_counter() - start
        time.sleep(0.5)
    raise TimeoutError(f"the head node did not listen on {port} within {timeout_s} s")


def reproduce(out: Path, only: str, extra: list[str]) -> tuple[float, Path]:
    command = [str(BIN / "safelane"), "reproduce", "--quick", "--seed", "0", "--only", only, "--no-progress",
               "--out", str(out), *extra]  # fmt: skip
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    (run,) = out.iterdir()
    return elapsed, run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="table1", help="experiment to run (default table1, quick grid)")
    ap.add_argument("--workers", type=int, default=2, help="processes for the reference run and Ray tasks per batch")
    ap.add_argument("--cpus", type=int, default=2, help="CPUs the head node offers")
    a = ap.parse_args()

    port = free_port()
    tmp = Path(tempfile.mkdtemp(prefix="slray-"))  # short: Ray's socket paths must stay under 108 characters
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0"}
    head = [str(BIN / "ray"), "start", "--head", f"--port={port}", f"--num-cpus={a.cpus}", "--include-dashboard=false",
            "--disable-usage-stats", f"--temp-dir={tmp / 'r'}", "--block"]  # fmt: skip
    print("$ ray " + " ".join(head[1:]), flush=True)
    proc = subprocess.Popen(head, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # fmt: skip
    try:
        up = wait_for(port)
        print(f"head node listening on 127.0.0.1:{port} after {up:.1f} s", flush=True)
        t_proc, run_p = reproduce(tmp / "out-process", a.only, ["--workers", str(a.workers)])
        print(f"safelane reproduce --quick --only {a.only} --workers {a.workers}: {t_proc:.1f} s", flush=True)
        address = f"127.0.0.1:{port}"
        t_ray, run_r = reproduce(tmp / "out-ray", a.only, ["--backend", "ray", "--ray-address", address,
                                                       "--workers", str(a.workers)])  # fmt: skip
        print(f"safelane reproduce --quick --only {a.only} --backend ray --ray-address {address} "
              f"--workers {a.workers}: {t_ray:.1f} s", flush=True)  # fmt: skip
        files = sorted(p.name for p in (run_p / "data").glob("*.csv"))
        same = [f for f in files if filecmp.cmp(run_p / "data" / f, run_r / "data" / f, shallow=False)]
        rows = sum(1 for _ in open(run_p / "data" / f"{a.only}_scenarios.csv")) - 1
        print(f"{len(same)} of {len(files)} CSVs byte-identical ({', '.join(files)}; {rows} scenarios)")
        if len(same) != len(files):
            raise SystemExit(f"DIFFERENT: {sorted(set(files) - set(same))}")
    finally:
        t0 = time.perf_counter()
        proc.send_signal(signal.SIGINT)  # ray start --block stops its node's processes, as on Ctrl-C
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # its own process group only
            proc.wait()
        print(f"head node stopped in {time.perf_counter() - t0:.1f} s (exit {proc.returncode})")
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
