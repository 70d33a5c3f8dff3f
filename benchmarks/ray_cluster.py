"""A sweep against a Ray cluster started the way a real one is: ``ray start --head`` on a port, then
``safelane reproduce --backend ray --ray-address 127.0.0.1:PORT`` (or, with ``--traffic``, the traffic sweep
``safelane traffic ... --backend ray``); the CSVs must equal ``--backend process``'s, byte for byte.

The head node runs in its own temp dir (so no other session's "running local cluster" lookup finds it) under
``ray start --block``, and is stopped by ending that one process group — never ``ray stop``, which stops every Ray
instance of the user on the machine. Needs the extra ``ray``.

    .venv/bin/python benchmarks/ray_cluster.py [--only table1] [--workers 2] [--cpus 2]
    .venv/bin/python benchmarks/ray_cluster.py --traffic [--seconds 300] [--warmup 60] [--penetration 0,0.5,1]
"""

from __future__ import annotations

import argparse
import filecmp
import hashlib
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


def run_command(command: list[str], out: Path) -> tuple[float, Path]:
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    (run,) = out.iterdir()
    return elapsed, run


def reproduce(out: Path, only: str, extra: list[str]) -> tuple[float, Path]:
    command = [str(BIN / "safelane"), "reproduce", "--quick", "--seed", "0", "--only", only, "--no-progress",
               "--out", str(out), *extra]  # fmt: skip
    return run_command(command, out)


def traffic(out: Path, a, extra: list[str]) -> tuple[float, Path]:
    command = [str(BIN / "safelane"), "traffic", "--penetration", a.penetration, "--demand", a.demand,
               "--seconds", str(a.seconds), "--warmup", str(a.warmup), "--no-progress", "--out", str(out),
               *extra]  # fmt: skip
    return run_command(command, out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="table1", help="experiment to run (default table1, quick grid)")
    ap.add_argument("--workers", type=int, default=2, help="processes for the reference run and Ray tasks per batch")
    ap.add_argument("--cpus", type=int, default=2, help="CPUs the head node offers")
    ap.add_argument("--traffic", action="store_true", help="the traffic sweep (safelane traffic) instead")
    ap.add_argument("--penetration", default="0,0.25,0.5,0.75,1", help="--traffic: penetration rates")
    ap.add_argument("--demand", default="4900", help="--traffic: total demands [veh/h]")
    ap.add_argument("--seconds", type=float, default=300.0, help="--traffic: simulated seconds per cell")
    ap.add_argument("--warmup", type=float, default=60.0, help="--traffic: warm-up [s]")
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
        address = f"127.0.0.1:{port}"
        if a.traffic:
            what = (f"traffic --penetration {a.penetration} --demand {a.demand} --seconds {a.seconds} "
                    f"--warmup {a.warmup}")
            t_proc, run_p = traffic(tmp / "out-process", a, ["--workers", str(a.workers)])
            t_ray, run_r = traffic(tmp / "out-ray", a, ["--backend", "ray", "--ray-address", address])
            folders, files = (run_p, run_r), ["cells.csv", "collisions.csv"]
        else:
            what = f"reproduce --quick --only {a.only}"
            t_proc, run_p = reproduce(tmp / "out-process", a.only, ["--workers", str(a.workers)])
            t_ray, run_r = reproduce(tmp / "out-ray", a.only, ["--backend", "ray", "--ray-address", address,
                                                               "--workers", str(a.workers)])  # fmt: skip
            folders = (run_p / "data", run_r / "data")
            files = sorted(p.name for p in folders[0].glob("*.csv"))
        print(f"safelane {what} --workers {a.workers}: {t_proc:.1f} s", flush=True)
        print(f"safelane {what} --backend ray --ray-address {address}: {t_ray:.1f} s", flush=True)
        same = [f for f in files if filecmp.cmp(folders[0] / f, folders[1] / f, shallow=False)]
        for f in files:
            digest = hashlib.sha256((folders[0] / f).read_bytes()).hexdigest()
            rows = sum(1 for _ in open(folders[0] / f)) - 1
            print(f"  {f}: {'identical' if f in same else 'DIFFERENT'} ({rows} rows; process sha256 {digest[:16]}…)")
        print(f"{len(same)} of {len(files)} CSVs byte-identical")
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
