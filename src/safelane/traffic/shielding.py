"""The one place equipped vehicles use the shield: :func:`decide`, one ``Shield.step`` per period over every
equipped vehicle that is changing lanes (a batch).

Rows come and go — a lane change starts, completes or is given up. :class:`ShieldPool` keeps the shield's state
aligned with the changers: each period where they changed, ``Shield.regroup`` keeps the rows of the changers that go
on and initialises and joins the rows of the new ones (the plan held at the start under the most conservative
assumptions; a neutral monitor snapshot, :mod:`safelane.shield.rows`), on the state as the shield holds it (the
compiled path's arrays stay packed); then one ``Shield.step``.

Today's shield takes the paper's world (F, a leader chain, the own-lane leaders); a richer situation (several
lanes, other lane changers) changes what :func:`decide` is given, not its callers.
"""

from __future__ import annotations

import numpy as np

from ..params import Params
from ..shield import Shield, ShieldConfig, Situation
from ..shield.decision import Decision
from ..shield.rows import take_rows


class ShieldPool:
    """One :class:`Shield` over a changing set of lane changes; ``calls`` counts its ``step`` calls."""

    def __init__(self, params: Params, variant: str = "CV_all", config: ShieldConfig | None = None):
        self.shield = Shield(params, variant=variant, config=config or ShieldConfig())
        self.params = params
        self.calls = 0

    def decide(self, situation: Situation, proposal, keep: np.ndarray, n_new: int) -> Decision:
        """``situation`` and ``proposal``: the rows of the changers that go on (``keep``: their rows in the last
        call's batch, in order) followed by ``n_new`` new ones."""
        sh = self.shield
        n_old = len(situation) - n_new
        if len(keep) != n_old:
            raise ValueError(f"keep has {len(keep)} rows; the situation has {n_old} continuing rows")
        keep = np.asarray(keep, np.int64)
        if n_new or not (0 < n_old == sh.rows and (keep == np.arange(n_old)).all()):
            # rows leave or join: the shield's state is regrouped as it is held (packed by the compiled path)
            new = take_rows(situation, np.arange(n_old, len(situation))) if n_new else None
            sh.regroup(keep, new, situation.t)
        self.calls += 1
        return sh.step(situation, proposal)


def decide(pool: ShieldPool, situation: Situation, proposal, keep: np.ndarray, n_new: int) -> Decision:
    """The equipped vehicles' use of the shield (the one function): one batched decision for every changer."""
    return pool.decide(situation, proposal, keep, n_new)
