"""Progress bars go to stderr: a command's standard output stays its result (JSON, a table) for pipes and files."""

from __future__ import annotations

import numpy as np
import pytest
import rich.progress

from safelane.sim import paper_scenarios, simulate_batch


@pytest.mark.parametrize("env", [{}, {"SAFELANE_NO_FUSED": "1"}])
def test_the_simulators_progress_bar_is_on_stderr(monkeypatch, env):
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    seen = []
    real = rich.progress.track

    def spy(items, *args, **kwargs):
        seen.append(kwargs.get("console"))
        return real(items, *args, **kwargs)

    monkeypatch.setattr(rich.progress, "track", spy)
    batch = paper_scenarios("CV_all", 1, 4.0, 4200 if not env else 8, np.random.default_rng(0))
    simulate_batch(batch, seed=0, progress=True, config=None)
    assert seen and all(console is not None and console.stderr for console in seen)
