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


def _mutated_closed_forms() -> list[str]:
    """The closed forms compiled into the kernels (``safety/_backend.jitable``) that mutmut has replaced by its
    trampoline in this process: empty outside mutation testing and for a group that mutates none of them."""
    import safelane.shield
    import safelane.sim  # noqa: F401  (with the shield: every module that marks a closed form)
    from safelane.safety import _backend

    return [f"{fn.__module__}.{fn.__name__}" for fn in _backend.ROW_FUNCTIONS if "mutmut" in fn.__code__.co_filename]


def pytest_collection_modifyitems(config, items):
    """Under mutation testing of a closed form that the kernels compile (``safety/_compile.py``), the tests marked
    ``compiled`` skip: they compare a kernel with the uncompiled path, and both are the one source, so they cannot tell
    a mutant from the original (and numba cannot compile mutmut's trampoline at all: every mutant would fail them,
    a kill that proves nothing). The uncompiled path is what mutation testing mutates; the other tests judge it."""
    if "MUTANT_UNDER_TEST" in os.environ and (mutated := _mutated_closed_forms()):
        import pytest

        skip = pytest.mark.skip(reason=f"mutation testing of closed forms the kernels compile ({mutated[0]}, …)")
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
