"""``write_csv``: the bytes of ``DataFrame.to_csv(index=False)`` on every dtype and edge value the run's tables hold,
and pandas itself wherever the fast path would not reproduce it (quoting, odd dtypes, an index)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from safelane.experiments.csv_writer import csv_text, write_csv

EDGE_FLOATS = [0.0, -0.0, 1.0, -1.5, 0.1 + 0.2, 3.0000000000000013, 1e-4, 1e-5, 123456789012345.6, 1e16, 1e-320,
               np.inf, -np.inf, np.nan, 5e-324, 1.7976931348623157e308, 2.5, 2.5]  # fmt: skip


def scenario_like(n: int = len(EDGE_FLOATS)) -> pd.DataFrame:
    """A table shaped like the run's scenario tables: ids, a planner name, rates, flags, counts, NaN times."""
    rng = np.random.default_rng(0)
    return pd.DataFrame(
        {
            "scenario_id": np.arange(n, dtype=np.int64),
            "planner": pd.array((["CV_all", "No_agg_assess", None] * n)[:n], dtype="str"),
            "decel": np.resize([2.0, 3.0, 4.0], n),
            "edge": np.asarray(EDGE_FLOATS[:n], dtype=np.float64),
            "gap_m": rng.normal(5, 3, n),
            "success": rng.random(n) < 0.5,
            "n_abort": rng.integers(-3, 40, n).astype(np.int32),
            "small": rng.integers(0, 200, n).astype(np.uint8),
            "label": np.array((["a b", "x"] * n)[:n], dtype=object),
        }
    )


def test_the_run_tables_dtypes_and_edge_values_match_pandas(tmp_path):
    frame = scenario_like()
    path = tmp_path / "t.csv"
    write_csv(frame, path)
    assert csv_text(frame) is not None  # this frame takes the fast path
    assert path.read_bytes() == frame.to_csv(index=False).encode()
    frame.to_csv(tmp_path / "pandas.csv", index=False)
    assert path.read_bytes() == (tmp_path / "pandas.csv").read_bytes()


def test_repeated_and_distinct_numbers_take_both_formatting_paths():
    repeated = pd.DataFrame({"a": np.tile([0.0, -0.0, np.nan, 0.1, 1e-7], 50), "b": np.tile([0, -7, 2**62], 250)[:250]})
    distinct = pd.DataFrame({"a": np.linspace(-1, 1, 250), "b": np.arange(-125, 125)})
    for frame in (repeated, distinct):
        assert csv_text(frame) == frame.to_csv(index=False)


@pytest.mark.parametrize(
    "frame",
    [
        pd.DataFrame({"a": ["x,y", "z"], "b": [1, 2]}),  # a comma: the csv module quotes it
        pd.DataFrame({"a": ['say "hi"', "z"], "b": [1, 2]}),
        pd.DataFrame({"a": ["two\nlines", "z"], "b": [1, 2]}),
        pd.DataFrame({"a": [" lead", "z"], "b": [1, 2]}),
        pd.DataFrame({"a,b": [1, 2], "c": [3, 4]}),  # a name that needs quoting
        pd.DataFrame({"a": [1.5, np.nan]}),  # one column: an empty row is written as ""
        pd.DataFrame({"a": [1.5, 2.5], "b": [1, 2]}, index=[3, 7]),  # not a default index
        pd.DataFrame({"a": np.array([0.1, 0.2], dtype=np.float32), "b": [1, 2]}),
        pd.DataFrame({"a": pd.array([1, None], dtype="Int64"), "b": [1, 2]}),
        pd.DataFrame({"a": pd.Categorical(["u", "v"]), "b": [1, 2]}),
        pd.DataFrame({"a": [True, None], "b": [1, 2]}),  # objects that are not strings
        pd.DataFrame({"a": [[1], [2, 3]], "b": [1, 2]}),  # unhashable objects
        pd.DataFrame({"a": pd.to_datetime(["2026-01-01", "2026-01-02"]), "b": [1, 2]}),
        pd.DataFrame({1: [1.5, 2.5], 2: [1, 2]}),  # names that are not strings
    ],
)
def test_what_the_fast_path_does_not_reproduce_is_left_to_pandas(tmp_path, frame):
    assert csv_text(frame) is None
    path = tmp_path / "t.csv"
    write_csv(frame, path)
    assert path.read_bytes() == frame.to_csv(index=False).encode()


@settings(max_examples=200, deadline=None)
@given(values=arrays(np.float64, st.integers(1, 60), elements=st.floats(allow_nan=True, allow_infinity=True)))
def test_any_float64_column_is_written_as_pandas_writes_it(values):
    frame = pd.DataFrame({"x": values, "y": np.resize(values[::-1], len(values))})
    assert csv_text(frame) == frame.to_csv(index=False)
