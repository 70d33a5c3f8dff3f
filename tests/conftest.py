"""Hypothesis profiles. ``ci`` (the default) is derandomized: the same examples on every run, so a test run is
reproducible and a red CI is a real regression, not a new draw. ``explore`` draws fresh examples each run and
keeps its database (``make fuzz``, or ``HYPOTHESIS_PROFILE=explore pytest``); a failure it finds becomes an
``@example`` in the test, so the deterministic run keeps it."""

from __future__ import annotations

import json
import os
from pathlib import Path

from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def _mutant_in_a_closed_form() -> str | None:
    """The mutant under test when it lies in a closed form that the kernels compile (one marked with
    ``safety/_backend.jitable``), else ``None`` (no mutation testing, mutmut's stats run, or a mutant elsewhere)."""
    name = os.environ.get("MUTANT_UNDER_TEST", "")
    if "__mutmut_" not in name:
        return None
    import safelane.shield
    import safelane.sim  # noqa: F401  (with the shield: every module that marks a closed form)
    from safelane.safety import _backend

    module, _, function = name.rpartition("__mutmut_")[0].rpartition(".x_")
    marked = {(fn.__module__, fn.__name__) for fn in _backend.ROW_FUNCTIONS}
    return name if (module, function) in marked else None


def pytest_collection_modifyitems(config, items):
    """While mutation testing mutates a closed form that the kernels compile (``safety/_compile.py``), the tests marked
    ``compiled`` skip: they compare a kernel with the array path, and under mutation the kernels compile the unmutated
    original (``_compile.source_of``: numba cannot compile mutmut's trampoline), so such a test would only restate that
    the mutant differs from the original — a kill that proves nothing. For every other mutant (a dispatch, a wrapper,
    the kernels' callers) they run as usual and judge it. The array path is what mutation testing mutates."""
    if (mutant := _mutant_in_a_closed_form()) is not None:
        import pytest

        skip = pytest.mark.skip(reason=f"{mutant} is in a closed form the kernels compile from its original")
        for item in items:
            if "compiled" in item.keywords:
                item.add_marker(skip)
    _order_for_mutation(items)


def _order_for_mutation(items):
    """Under mutation testing (mutmut sets ``MUTANT_UNDER_TEST``; docs/testing.md): the selected tests fastest first,
    by the durations mutmut recorded in its stats run. mutmut stops a mutant's run at the first failing test but
    passes the selected tests in the order of a set, so without this a killed mutant often runs slow tests before the
    cheap one that kills it. Order only: the verdicts are the same. ``SAFELANE_MUTATE_ORDER=0`` turns it off."""
    if "MUTANT_UNDER_TEST" not in os.environ or os.environ.get("SAFELANE_MUTATE_ORDER") == "0":
        return
    stats = Path("mutmut-stats.json")
    if not stats.exists():
        return
    durations = json.loads(stats.read_text(encoding="utf-8")).get("duration_by_test", {})
    items.sort(key=lambda item: durations.get(item.nodeid, 0.0))
