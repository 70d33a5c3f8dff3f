"""Hypothesis profiles. ``ci`` (the default) is derandomized: the same examples on every run, so a test run is
reproducible and a red CI is a real regression, not a new draw. ``explore`` draws fresh examples each run and
keeps its database (``make fuzz``, or ``HYPOTHESIS_PROFILE=explore pytest``); a failure it finds becomes an
``@example`` in the test, so the deterministic run keeps it."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
