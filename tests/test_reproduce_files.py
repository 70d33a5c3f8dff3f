"""``reproduce``'s "figures and files" step (``write_files``): one process or two write the same files, byte for
byte, in the same order; every CSV is what ``DataFrame.to_csv`` writes; each experiment gets its own figure."""

from __future__ import annotations

from pathlib import Path

import pytest

from safelane.experiments.registry import EXPERIMENTS
from safelane.experiments.reproduce import _has_pyarrow, write_files
from safelane.experiments.runner import run_experiment
from test_reproduce import PRESET, tiny_configs


@pytest.fixture(scope="module")
def results():
    cache, configs = {}, tiny_configs()
    return {
        name: run_experiment(name, configs.get(name), preset=PRESET, seed=3, quick=True, cache=cache)
        for name in EXPERIMENTS
    }


@pytest.fixture(scope="module")
def written(results, tmp_path_factory):
    """The files written by one process and by two."""
    out = {}
    for workers in (1, 2):
        run_dir = tmp_path_factory.mktemp(f"workers{workers}")
        (run_dir / "data").mkdir()
        out[workers] = (run_dir, write_files(results, run_dir, PRESET, workers))
    return out


def _files(run_dir: Path) -> dict[str, bytes]:
    return {p.relative_to(run_dir).as_posix(): p.read_bytes() for p in sorted(run_dir.rglob("*")) if p.is_file()}


def test_one_process_and_two_write_the_same_files(written):
    (dir1, files1), (dir2, files2) = written[1], written[2]
    one, two = _files(dir1), _files(dir2)
    assert sorted(one) == sorted(two)
    assert {Path(k).suffix for k in one} >= {".csv", ".png", ".svg"}
    for name, data in one.items():
        assert data == two[name], name  # CSVs, PNGs and SVGs alike
    assert files1.data_files == files2.data_files
    assert [p.relative_to(dir1) for ps in files1.figures.values() for p in ps] == [
        p.relative_to(dir2) for ps in files2.figures.values() for p in ps
    ]
    assert files1.claims == files2.claims and files1.mae == files2.mae


def test_data_files_are_listed_in_experiment_order_and_every_one_is_written(results, written):
    run_dir, files = written[2]
    suffixes = (".csv", ".parquet") if _has_pyarrow() else (".csv",)
    expected = [
        Path("data") / f"{name}_{kind}{suffix}"
        for name, res in results.items()
        for kind, frame in (("scenarios", res.table), ("summary", res.summary), ("trace", res.trace))
        if frame is not None
        for suffix in suffixes
    ] + [Path("data/claims.csv"), Path("data/table1_side_by_side.csv")]
    assert files.data_files == expected
    assert sorted(p.name for p in (run_dir / "data").iterdir()) == sorted(p.name for p in expected)


def test_every_csv_is_what_pandas_writes(results, written):
    run_dir, files = written[2]
    for name, res in results.items():
        for kind, frame in (("scenarios", res.table), ("summary", res.summary), ("trace", res.trace)):
            if frame is not None:
                data = (run_dir / "data" / f"{name}_{kind}.csv").read_bytes()
                assert data == frame.to_csv(index=False).encode(), (name, kind)
    assert (run_dir / "data" / "table1_side_by_side.csv").read_bytes() == files.side_by_side.to_csv(
        index=False
    ).encode()


def test_each_experiment_gets_its_own_figure(written):
    for workers, (run_dir, files) in written.items():
        assert list(files.figures) == list(EXPERIMENTS), workers  # in the experiments' order, as the report reads
        for name, paths in files.figures.items():
            assert [(p.parent, p.name) for p in paths] == [
                (run_dir / "figures", f"{name}.png"),
                (run_dir / "figures", f"{name}.svg"),
            ]
            assert all(p.stat().st_size > 0 for p in paths)
