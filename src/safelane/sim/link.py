"""V2X emulation in the closed loop: lost, late and stale messages (``SimConfig.v2x_loss``, ``v2x_latency_periods``,
``v2x_max_age_s``).

Off by default (loss 0, latency 0): the ego then knows the connected vehicles' current states every period, as in
the paper. On, every connected vehicle sends one message per period — its state and its last applied
acceleration — which is lost with probability ``v2x_loss`` (independently per sender and period, counter-based
draws) and otherwise arrives ``v2x_latency_periods`` periods later. The ego keeps the latest message received from
each sender and builds its view of the chain with :func:`safelane.v2x.received_chain`, the staleness fallback of
:mod:`safelane.v2x`: fresh senders extrapolated with their reported acceleration, the first stale one counted as
non-connected (it becomes ``L(N+1)``, moved as braking at ``a_x_d`` since its message). ``L1`` itself is also
sensed, so its state is always exact; its *connectedness* (hence its promise) needs a fresh message. ``F``'s
declared intent counts only while its message is fresh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..tolerances import TIME_TOL_S
from ..v2x import received_chain
from .rng import counter_uniform


@dataclass(frozen=True)
class Link:
    """The latest message received from each target-lane slot (``(B, K)``: timestamp, position, speed, reported
    acceleration) and the messages still in flight (oldest first)."""

    t: np.ndarray
    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    in_flight: tuple

    @classmethod
    def start(cls, x, v) -> Link:
        """At ``t = 0`` the ego holds every sender's current state (the lane change starts from a known world)."""
        return cls(t=np.zeros(x.shape), p=x.copy(), v=v.copy(), a=np.zeros(x.shape), in_flight=())

    def update(self, t: float, x, v, acc, step: int, seed: int, scenario_id, loss: float, latency: int) -> Link:
        """Send this period's messages and deliver those due now."""
        slots = np.arange(x.shape[1])[None, :]
        arrives = np.ones(x.shape, bool)
        if loss > 0.0:
            arrives = counter_uniform(seed, scenario_id[:, None], step, slots, 11) >= loss
        in_flight = (*self.in_flight, (np.full(x.shape, t), x, v, acc, arrives))
        if len(in_flight) <= latency:
            return Link(self.t, self.p, self.v, self.a, in_flight)
        (tm, pm, vm, am, ok), rest = in_flight[0], in_flight[1:]
        return Link(
            t=np.where(ok, tm, self.t),
            p=np.where(ok, pm, self.p),
            v=np.where(ok, vm, self.v),
            a=np.where(ok, am, self.a),
            in_flight=rest,
        )

    def chain_view(self, now: float, sensed_x1, sensed_v1, chain_connected, prm: Params, max_age_s: float):
        """The ego's view of ``L1..L(K-1)``: ``(p, v, n_connected, stale)`` (see :func:`safelane.v2x.received_chain`);
        ``L1``'s state is the sensed one."""
        p, v, n, stale = received_chain(
            self.t[:, 1:], self.p[:, 1:], self.v[:, 1:], self.a[:, 1:], chain_connected, now, prm, max_age_s=max_age_s
        )
        p[:, 0], v[:, 0] = sensed_x1, sensed_v1
        return p, v, n, stale

    def fresh(self, slot: int, now: float, max_age_s: float) -> np.ndarray:
        """``(B,)`` the latest message from ``slot`` is fresh at ``now``."""
        return now - self.t[:, slot] <= max_age_s + TIME_TOL_S
