"""The envs' scenario distribution: :class:`ScenarioSampler` draws each episode's scenario from the sub-env's own
generator (the paper's sampler, ``N`` and ``a_x_N+1_d`` drawn per episode), one row at a time or many rows at once
with the same draws."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from ..planners.variants import VARIANT_NAMES, get_variant
from ..sim.scenario import ScenarioBatch, ScenarioConfig, paper_scenarios
from .rows import pad_vehicles

#: The bit generators whose raw words (``random_raw``) are the 64-bit draws their ``Generator`` builds on (all of
#: NumPy's but ``MT19937``, whose raw words have 32 bits): for them ``Generator.random()`` is ``(word >> 11)·2⁻⁵³``
#: and ``Generator.integers(0, 2**62)`` is ``word >> 2`` (Lemire's bounded draw with a power-of-two range: one word,
#: never rejected), so :meth:`ScenarioSampler.draw_many` takes a row's draws in one call
#: (``tests/test_envs.py`` checks the scenarios against :meth:`ScenarioSampler.draw` for each generator).
_WORD_GENERATORS = (np.random.PCG64, np.random.PCG64DXSM, np.random.Philox, np.random.SFC64)
_DOUBLE_UNIT = 1.0 / 9007199254740992.0  # 2⁻⁵³


@dataclasses.dataclass(frozen=True)
class ScenarioSampler:
    """Draws one scenario from a generator: the paper's sampler with ``N`` drawn from ``n_leaders`` and
    ``a_x_N+1_d`` from ``decel`` (a number, or ``(lo, hi)`` for ``U[lo, hi]``), padded to ``max(n_leaders) + 2``
    vehicles so that every episode fits one batch."""

    variant: str = "CV_all"
    n_leaders: tuple[int, ...] = (3,)
    decel: tuple[float, float] = (5.0, 5.0)
    scenario: ScenarioConfig = dataclasses.field(default_factory=ScenarioConfig)
    p_v: float = 0.0

    @classmethod
    def build(cls, variant="CV_all", n_leaders=3, decel=5.0, scenario=None, p_v=0.0) -> ScenarioSampler:
        get_variant(variant)
        leaders = (n_leaders,) if np.isscalar(n_leaders) else tuple(n_leaders)
        if not leaders or any(int(n) != n or n < 0 for n in leaders):
            raise ValueError(f"n_leaders must be a non-negative integer or a sequence of them; got {n_leaders!r}")
        span = (float(decel), float(decel)) if np.isscalar(decel) else tuple(float(d) for d in decel)
        if len(span) != 2 or not 0.0 < span[0] <= span[1]:
            raise ValueError(f"decel must be a positive number or a range (lo, hi) with 0 < lo <= hi; got {decel!r}")
        if isinstance(scenario, dict):
            scenario = ScenarioConfig(**scenario)
        return cls(variant, tuple(int(n) for n in leaders), span, scenario or ScenarioConfig(), float(p_v))

    @property
    def width(self) -> int:
        return max(self.n_leaders) + 2

    def _settings(self, rng: np.random.Generator) -> tuple[int, float]:
        n = self.n_leaders[rng.integers(len(self.n_leaders))] if len(self.n_leaders) > 1 else self.n_leaders[0]
        lo, hi = self.decel
        return n, (rng.uniform(lo, hi) if hi > lo else lo)

    def draw(self, rng: np.random.Generator) -> ScenarioBatch:
        """One scenario through :func:`~safelane.sim.paper_scenarios` itself (the reference :meth:`draw_many`
        is tested against)."""
        n, decel = self._settings(rng)
        row = paper_scenarios(self.variant, n, decel, 1, rng, self.scenario, p_v=self.p_v)
        # A fresh id per episode keys the simulator's counter-based draws (promise violations, sensor noise).
        row = dataclasses.replace(row, scenario_id=rng.integers(0, 2**62, size=1))
        return pad_vehicles(row, self.width)

    def draw_many(self, rngs: Sequence[np.random.Generator]) -> ScenarioBatch:
        """One scenario from each generator, as one batch: the same draws in the same order as :meth:`draw`, hence
        the same scenarios, but the arrays are built once for all rows (``paper_scenarios`` per row costs ~0.1 ms,
        a third of a vector step at 1,024 envs)."""
        cfg, k = self.scenario, self.width
        m = len(rngs)
        n = np.full(m, self.n_leaders[0], np.int64)
        lo, hi = self.decel
        first = 0 if hi > lo else 1  # a fixed decel draws no uniform: u's first column stays 0.0
        several = len(self.n_leaders) > 1
        # Per row, the draws of _settings and paper_scenarios(samples=1) in their order: N (where several), the
        # uniforms (decel, gap, ego_vx, F connected, F aggressive, one per leader; uniform(a, b) is a + (b - a)·random()
        # on the same stream) and the id. Each row's uniforms land in a row of u; past a row's own leaders u is masked.
        if all(type(getattr(rng, "bit_generator", None)) in _WORD_GENERATORS for rng in rngs):
            # The same draws as words: one call per row (see _WORD_GENERATORS)
            words = np.zeros((m, 6 + max(self.n_leaders)), np.uint64)
            if several:
                for i, rng in enumerate(rngs):
                    n[i] = self.n_leaders[rng.integers(len(self.n_leaders))]
                    words[i, first : 6 + n[i]] = rng.bit_generator.random_raw(6 + n[i] - first)
            elif m:
                words[:, first:] = [rng.bit_generator.random_raw(words.shape[1] - first) for rng in rngs]
            u = (words >> np.uint64(11)) * _DOUBLE_UNIT
            sid = (words[np.arange(m), 5 + n] >> np.uint64(2)).astype(np.int64)
        else:
            u, sid = np.ones((m, 5 + max(self.n_leaders))), np.zeros(m, np.int64)
            for i, rng in enumerate(rngs):
                if several:
                    n[i] = self.n_leaders[rng.integers(len(self.n_leaders))]
                rng.random(out=u[i, first : 5 + n[i]])
                sid[i] = rng.integers(0, 2**62)
        if first:
            u[:, 0] = 0.0
        decel, gap, ego_vx, f_conn_u, f_aggr_u = u[:, :5].T
        leaders = max(self.n_leaders)
        human = np.zeros((m, k), bool)
        human[:, 1 : leaders + 1] = (u[:, 5 : 5 + leaders] < cfg.human_share) & (np.arange(leaders) < n[:, None])
        decel = lo + (hi - lo) * decel if hi > lo else np.full(m, lo)
        gap = cfg.gap[0] + (cfg.gap[1] - cfg.gap[0]) * gap
        ego_vx = cfg.ego_speed[0] + (cfg.ego_speed[1] - cfg.ego_speed[0]) * ego_vx
        f_connected = f_conn_u < cfg.follower_connected_share
        slots = np.arange(k)[None, :]
        last = n[:, None] + 1  # L(N+1)'s slot; beyond it: padding
        x = np.where(slots == 0, -1.0, np.minimum(slots, last)) * gap[:, None] + 1e6 * np.maximum(slots - last, 0)
        connected = (slots >= 1) & (slots <= n[:, None])
        connected[:, 0] = f_connected
        return ScenarioBatch(
            ego_x=np.zeros(m),
            ego_y=np.zeros(m),
            ego_vx=ego_vx,
            ego_vy=np.zeros(m),
            x=x,
            v=np.full((m, k), cfg.traffic_speed),
            valid=slots <= last,
            connected=connected,
            human=human,
            promise_decel=np.full((m, k), cfg.promise_decel),
            promise_accel=np.full((m, k), cfg.promise_accel),
            n_connected=n,
            follower_aggressive=~f_connected & (f_aggr_u < cfg.follower_aggressive_share),
            decel_last=decel,
            p_v=np.full(m, self.p_v),
            variant=np.full(m, VARIANT_NAMES.index(self.variant)),
            scenario_id=sid,
        )
