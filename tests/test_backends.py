"""Issue 13: ``map_chunks`` on local processes and on Ray — results in job order, the first failure in job order,
messages from running jobs; the same CSVs, byte for byte, from ``reproduce`` on every backend and worker count;
the falsifier's streams on Ray; bad inputs and a missing Ray as one line with exit status 2.

One local Ray instance serves the whole module (a start costs 3–5 s); the Ray tests skip where Ray is not
installed (``pip install 'safelane[ray]'``; ``make install`` installs it)."""

from __future__ import annotations

import filecmp
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from safelane import Params
from safelane.cli import app
from safelane.errors import InputError
from safelane.experiments import falsify as fz
from safelane.experiments.calibration import Preset
from safelane.experiments.reproduce import reproduce
from safelane.parallel import BACKENDS, Backend, as_backend, map_chunks, probe, ray_available, ray_session
from safelane.sim.engine import SimConfig

needs_ray = pytest.mark.skipif(not ray_available(), reason="ray is not installed: pip install 'safelane[ray]'")

#: Later jobs finish first: results must still come back in job order.
SLOW_FIRST = [(float(k), 0.2 if k < 2 else 0.0) for k in range(6)]
PRESET = Preset("test", Params(), SimConfig(horizon_s=4.0), {})  # a short horizon keeps the runs fast
EXPERIMENTS = ("table1", "penetration", "table1_safe_mode")


@pytest.fixture(scope="module")
def ray_cluster():
    """One local Ray instance for the module (or the cluster the environment names), shut down at its end."""
    if not ray_available():
        pytest.skip("ray is not installed: pip install 'safelane[ray]'")
    with ray_session(num_cpus=2) as ray:
        yield ray


def tiny_configs() -> dict:
    from safelane.experiments.registry import EXPERIMENTS as REGISTRY

    return {name: REGISTRY[name].config_type(**{**REGISTRY[name].quick, "samples": 7}) for name in EXPERIMENTS}


def reproduce_csvs(base, workers) -> dict:
    run = reproduce(base, seed=5, quick=True, preset=PRESET, progress=False, experiments=EXPERIMENTS,
                    configs=tiny_configs(), workers=workers)  # fmt: skip
    files = sorted((run / "data").glob("*.csv"))
    assert len(files) >= 2 * len(EXPERIMENTS)
    return {f.name: f for f in files}


def assert_same_files(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for name in a:
        assert filecmp.cmp(a[name], b[name], shallow=False), name


# --- map_chunks --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("workers", [1, 2])
def test_process_backend_keeps_job_order(workers):
    out = map_chunks(probe, SLOW_FIRST, "process", workers)
    assert [v for v, _, _ in out] == [v for v, _ in SLOW_FIRST]
    pids = {pid for _, pid, _ in out}
    assert (pids == {__import__("os").getpid()}) == (workers == 1)  # workers=1 runs here


@needs_ray
def test_ray_backend_keeps_job_order(ray_cluster):
    out = map_chunks(probe, SLOW_FIRST, "ray", 2)
    assert [v for v, _, _ in out] == [v for v, _ in SLOW_FIRST]
    assert __import__("os").getpid() not in {pid for _, pid, _ in out}
    assert map_chunks(probe, [], "ray") == []


@pytest.mark.parametrize("backend", ["process-1", "process-2", pytest.param("ray", marks=needs_ray)])
def test_the_first_failure_in_job_order_is_raised(backend, request):
    name, _, workers = backend.partition("-")
    if name == "ray":
        request.getfixturevalue("ray_cluster")
    # Job 1 fails after job 3 has failed: the error reported is job 1's, as a ValueError on every backend.
    jobs = [(0.0, 0.0), (-1.0, 0.0), (2.0, 0.3), (-3.0, 0.0)]
    with pytest.raises(ValueError, match=r"negative value -1\.0"):
        map_chunks(probe, jobs, name, int(workers) if workers else 2)


@pytest.mark.parametrize("backend", ["process-1", "process-2", pytest.param("ray", marks=needs_ray)])
def test_messages_from_running_jobs_reach_the_progress_callback(backend, request):
    name, _, workers = backend.partition("-")
    if name == "ray":
        request.getfixturevalue("ray_cluster")
    seen = []
    out = map_chunks(probe, SLOW_FIRST, name, int(workers) if workers else 2, progress=seen.append)
    assert sorted(seen) == [v for v, _ in SLOW_FIRST] and len(out) == len(SLOW_FIRST)


def test_bad_backend_arguments_name_the_argument():
    with pytest.raises(InputError, match="backend must be one of process, ray; got 'spark'"):
        map_chunks(probe, SLOW_FIRST, "spark")
    with pytest.raises(InputError, match="workers must be an integer >= 1"):
        Backend("process", 0)
    with pytest.raises(InputError, match="workers must be an integer >= 1"):
        Backend("ray", 2.5)
    with pytest.raises(InputError, match="use backend 'ray'"):
        Backend("process", 2, "127.0.0.1:6379")
    assert BACKENDS == ("process", "ray")
    assert as_backend(3) == Backend("process", 3) and as_backend(Backend("ray")).name == "ray"
    assert Backend("ray", 4, "head:6379").cli_args() == ["--backend", "ray", "--workers", "4", "--ray-address",
                                                          "head:6379"]  # fmt: skip


def test_missing_ray_is_an_install_hint(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as if it were not installed
    with pytest.raises(ImportError, match=r"pip install 'safelane\[ray\]'"):
        map_chunks(probe, SLOW_FIRST, "ray")
    for command in (["simulate", "--samples", "10"], ["reproduce", "--quick"], ["calibrate"], ["falsify"]):
        result = CliRunner().invoke(app, [*command, "--backend", "ray", "--out", str(tmp_path / "o")])
        assert result.exit_code == 2, result.output
        assert "pip install 'safelane[ray]'" in result.output and "Traceback" not in result.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--backend", "spark"], "'spark' is not a backend; allowed: process, ray"),
        (["--ray-address", "head:6379"], "needs --backend ray"),
        (["--workers", "0"], "--workers"),
    ],
)
@pytest.mark.parametrize("command", ["simulate", "reproduce", "calibrate", "falsify"])
def test_bad_backend_options_are_one_line_with_status_2(command, args, message, tmp_path):
    result = CliRunner().invoke(app, [command, *args, "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    assert message in result.output and "Traceback" not in result.output
    assert not (tmp_path / "o").exists()  # checked before any work


@needs_ray
def test_an_address_where_no_cluster_answers_is_named(tmp_path):
    # A fresh interpreter: this one holds the module's Ray connection.
    safelane = Path(sys.executable).with_name("safelane")
    command = [str(safelane), "simulate", "--backend", "ray", "--ray-address", "127.0.0.1:9", "--out", str(tmp_path)]
    result = subprocess.run(command, capture_output=True, text=True)
    assert result.returncode == 2, result.stderr
    assert "--ray-address" in result.stderr and "no Ray cluster answers at '127.0.0.1:9'" in result.stderr
    assert "Traceback" not in result.stderr


@needs_ray
def test_a_second_cluster_in_one_process_is_refused(ray_cluster):
    with pytest.raises(InputError, match="already connected to"):
        map_chunks(probe, SLOW_FIRST, "ray", 2, "127.0.0.1:9")


def test_import_safelane_does_not_import_ray():
    code = ("import sys, safelane, safelane.sim, safelane.parallel, safelane.experiments.reproduce, safelane.cli; "
            "assert 'ray' not in sys.modules, 'ray imported'")  # fmt: skip
    subprocess.run([sys.executable, "-c", code], check=True)


# --- the same numbers everywhere ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def process_csvs(tmp_path_factory):
    return reproduce_csvs(tmp_path_factory.mktemp("w1"), 1)


def test_reproduce_is_byte_identical_with_2_processes(process_csvs, tmp_path):
    assert_same_files(process_csvs, reproduce_csvs(tmp_path, 2))


@needs_ray
def test_reproduce_is_byte_identical_on_ray(process_csvs, tmp_path, ray_cluster):
    # 3 chunks on a 2-CPU instance: other cuts than the processes', the same bytes.
    assert_same_files(process_csvs, reproduce_csvs(tmp_path, Backend("ray", 3)))


@needs_ray
def test_simulate_command_gives_the_same_csv_on_ray(tmp_path, ray_cluster):
    base = ["simulate", "--samples", "60", "--leaders", "3", "--no-progress"]
    runs = {}
    for label, extra in (("process", []), ("ray", ["--backend", "ray", "--workers", "2"])):
        result = CliRunner().invoke(app, [*base, *extra, "--out", str(tmp_path / label)])
        assert result.exit_code == 0, result.output
        (runs[label],) = (tmp_path / label).iterdir()
    assert filecmp.cmp(runs["process"] / "scenarios.csv", runs["ray"] / "scenarios.csv", shallow=False)
    assert '"backend": "ray"' in (runs["ray"] / "run.json").read_text()


@needs_ray
def test_falsifier_streams_on_ray_give_the_processes_report(ray_cluster):
    kwargs = dict(scenarios=20, minutes=0.0, seed=2, method="random", batch_size=10)  # one batch per stream
    seen = []
    on_ray = fz.falsify(**kwargs, workers=Backend("ray", 2), on_batch=lambda r: seen.append(r.simulated))
    local = fz.falsify(**kwargs, workers=2)
    strip = lambda r: {k: v for k, v in r.summary().items() if k != "wall_s"}  # noqa: E731
    assert strip(on_ray) == strip(local) and on_ray.min_ratio == local.min_ratio
    assert seen and max(seen) == on_ray.simulated  # progress came back while the streams ran
