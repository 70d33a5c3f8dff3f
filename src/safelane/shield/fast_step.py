"""The shield's period in one compiled call: :class:`Packed` state and :func:`step`, which :class:`~.core.Shield`
runs where :func:`refusals` is empty (numba present, ``SAFELANE_NO_NUMBA`` not ``1``).

A stateful :class:`~.core.Shield` keeps its state packed into arrays between periods (:class:`Packed`): one call of
:func:`._fast_period.period_kernel` updates it, and the :class:`~.decision.Decision` is built from its arrays. The
functional :class:`~.core.ShieldState` is unpacked only when someone reads ``Shield.state``. The decisions and the
state are the NumPy stages' (``core.step``) bits: ``tests/test_fast_period.py``.

**Dispatch never guesses.** :func:`refusals` names every reason a period cannot run compiled, from the
configuration's own field list (:data:`COMPILED`: each :class:`~.config.ShieldConfig` field with the values the kernel
implements; a field missing there refuses, so a new setting is never run at its default) and from what the
situation and the state carry (:data:`SITUATION_FIELDS`: any field not classified there — the world model's other
vehicles are folded into the roles first, :func:`.core.fold_world`; commands in flight that the kernel's queue cannot
hold; another decision rule). A
refused period runs the stages; ``Shield.last_path`` says which ran, ``Shield.refusals(situation)`` why.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from ..params import Params
from ..safety._backend import FEASIBILITY_TOL_M
from ..safety.evasion import fast_kernel
from ..safety.lateral import LATERAL_TOL_M
from ..safety.plan import EvasionPlan
from ..tolerances import TIME_TOL_S
from .assessment import AssessmentState
from .command import Command, InFlight
from .config import ShieldConfig
from .decide import own_completion_level, own_margin
from .decision import Decision
from .monitor import TOL_M, Anchor, Breach, Snapshot
from .realworld import delay_periods
from .rules import rule_rows, uncompiled_rules

#: The knots of an aborting row's command (``plan_knots``': the period's ends and the plan's six switches), as the
#: kernel's queue of commands in flight holds them.
KNOTS = 8

#: Each :class:`ShieldConfig` field and the values the compiled period implements (``None``: every value).
COMPILED: dict[str, tuple | None] = {
    "assessment": ("observed", "truth", "slow"),
    "assess_window": None,
    "assess_threshold": None,
    "monitor": None,
    "completion": ("commit_guard", "paper_evasion"),
    "assess_delay_s": None,  # read by the 'slow' assessment
    "assess_miss": None,  # read by the 'slow' assessment
    "enabled": (True,),
    "actuation_delay_s": None,  # whole periods (realworld.delay_periods); the commands in flight packed (Packed.queue)
    "own_lane": None,
    "sensing": None,  # the sensing box's corners, the chain at them and the monitor's anchor (sense_arrays)
}


def kernel():
    """The compiled period's module, or ``None`` (numba missing, or ``SAFELANE_NO_NUMBA=1``)."""
    if fast_kernel() is None:
        return None
    from . import _fast_period

    return _fast_period


def refusals(config: ShieldConfig, variant, batch: int) -> list[str]:
    """Why a period with this configuration and variant cannot run compiled (empty: it can)."""
    out = []
    for name in type(config).model_fields:
        allowed = COMPILED.get(name, ())
        value = getattr(config, name)
        if allowed is not None and value not in allowed:
            out.append(f"ShieldConfig.{name}={value!r}" + ("" if name in COMPILED else " (not classified)"))
    other = uncompiled_rules(rule_rows(variant, batch))
    if other:
        out.append(f"rows decided by a rule the compiled period does not implement: {', '.join(other)}")
    return out


#: Each :class:`~.situation.Situation` field: ``"read"`` (the kernel reads it) or ``"refused"`` (refused where not
#: ``None``).
SITUATION_FIELDS: dict[str, str] = {
    **dict.fromkeys(("t", "ego_x", "ego_y", "ego_vx", "ego_vy", "f_x", "f_v", "f_connected", "f_collaborative",
                     "chain_x", "chain_v", "chain_promise", "chain_human", "n_connected", "f_speed_observed",
                     "v2x_stale", "own_x", "own_v", "own_promise", "own_n_connected"), "read"),
    "f_aggressive_truth": "read",
    **dict.fromkeys(("err_f", "err_chain", "err_own"), "read"),  # where ShieldConfig.sensing: sense_arrays
}


@functools.lru_cache(maxsize=8)
def _refused_fields(cls, kinds: tuple) -> tuple[str, ...]:
    """The fields of the situation class ``cls`` that refuse wherever they are set; ``kinds``:
    :data:`SITUATION_FIELDS`' items (the key of the cache, so that a change of the table is seen)."""
    table = dict(kinds)
    return tuple(f.name for f in dataclasses.fields(cls) if table.get(f.name, "refused") == "refused")


def situation_refusals(situation, config: ShieldConfig, state) -> list[str]:
    """Why this situation and state cannot run compiled (empty: they can). A :class:`~.situation.Situation` field
    that :data:`SITUATION_FIELDS` does not classify refuses wherever it is set."""
    refused = _refused_fields(type(situation), tuple(SITUATION_FIELDS.items()))
    out = [f"Situation.{name}" for name in refused if getattr(situation, name) is not None]
    if state is not None:
        if state.pending is None and config.actuation_delay_s > 0.0:
            out.append("an actuation delay without commands in flight")
        elif state.pending is not None and any(c.rows.size and c.knots.shape[1] != KNOTS
                                               for c in state.pending.commands):  # fmt: skip
            out.append(f"commands in flight with other than {KNOTS} knots")
    return out


@dataclass
class Packed:
    """A :class:`~.core.ShieldState` as the kernel's arrays (see :mod:`._fast_period` for the columns)."""

    t: float
    plan: np.ndarray  # (B, len(PLAN)), column-major
    history: np.ndarray  # (B, window)
    count: np.ndarray  # (B,) int64
    st: np.ndarray  # (B, len(STATE_F))
    sk: np.ndarray  # (B, len(STATE_B)) bool
    snapshot: tuple | None  # (chain_x, chain_v, bounds, n_connected) of the last period, or None
    slow: bool = False  # the belief is the 'slow' assessment's (policies.SlowState): its draws and belief packed too
    #: The commands in flight (actuation delay), oldest first, or None: ``(knots (B, d, KNOTS), seg (B, d, 2,
    #: KNOTS − 1), acc (B, d, 2), flags (B, d, 2))`` — an aborting row's knots and its segments' ``a_x``, ``a_y``
    #: (zeros for the other rows), each row's ``a_x``, ``a_y`` at the period's start, and its completing and aborting
    #: flags (:class:`~.command.Command`'s fields, row by row).
    queue: tuple | None = None
    anchor: tuple | None = None  # the monitor's cumulative anchor (f (B, len(ANCHOR_F)), chain_x, chain_v, bounds,
    # n_connected), or None (no sensing box)

    @classmethod
    def of(cls, state) -> Packed:
        from ._fast_period import PLAN, STATE_B, STATE_F
        from .policies import SlowState

        n = len(state.completed)
        plan = np.empty((n, len(PLAN)), order="F")
        for j, name in enumerate(PLAN):
            plan[:, j] = getattr(state.plan, name)
        last, belief, breach = state.last, state.belief, state.breach
        slow = isinstance(belief, SlowState)
        inner = belief.inner if slow else belief
        st = np.empty((n, len(STATE_F)))
        st[:, 0], st[:, 1], st[:, 2] = state.plan_t0, inner.first_collaborative_s, breach.first_s
        st[:, 7] = belief.delay_s if slow else 0.0
        sk = np.empty((n, len(STATE_B)), bool)
        sk[:, 0], sk[:, 1], sk[:, 2], sk[:, 3] = state.plan_f_aggr, inner.latched, inner.aggressive, state.completed
        sk[:, 5:10] = breach.flags
        sk[:, 10], sk[:, 11] = (belief.missed, belief.aggressive) if slow else (False, inner.aggressive)
        snapshot = anchor = None
        if last is None:
            st[:, 3:], sk[:, 4] = 0.0, False
        else:
            st[:, 3], st[:, 4], st[:, 5], st[:, 6] = last.f_x, last.f_v, last.f_limit, last.plan_l1_decel
            sk[:, 4] = last.active
            snapshot = (last.chain_x, last.chain_v, last.bounds, np.asarray(last.n_connected, np.int64))
            anchor = None if last.anchor is None else _pack_anchor(last.anchor, n)
        return cls(float(state.t), plan, inner.history.copy(), np.asarray(inner.count, np.int64).copy(), st, sk,
                   snapshot, slow, _queue_of(state.pending, n), anchor)  # fmt: skip

    def take(self, rows) -> Packed:
        """The rows ``rows`` only, in that order (copies)."""
        snapshot = None if self.snapshot is None else tuple(a[rows] for a in self.snapshot)
        queue = None if self.queue is None else tuple(a[rows] for a in self.queue)
        anchor = None if self.anchor is None else tuple(a[rows] for a in self.anchor)
        return Packed(self.t, np.asfortranarray(self.plan[rows]), self.history[rows], self.count[rows],
                      self.st[rows], self.sk[rows], snapshot, self.slow, queue, anchor)  # fmt: skip

    def join(self, other: Packed) -> Packed:
        """These rows, then ``other``'s (its time is this one's; both have a snapshot, or neither)."""
        if (self.snapshot is None) != (other.snapshot is None):
            raise ValueError("Packed.join: one state has a monitor snapshot and the other has none")
        if (self.queue is None) != (other.queue is None) or (
                self.queue is not None and self.queue[0].shape[1] != other.queue[0].shape[1]):  # fmt: skip
            raise ValueError("Packed.join: the two states hold different numbers of commands in flight")
        if (self.anchor is None) != (other.anchor is None):
            raise ValueError("Packed.join: one state has the monitor's anchor (a sensing box) and the other has none")
        snapshot, queue, anchor = (None if mine is None else tuple(
            np.concatenate([a, b]) for a, b in zip(mine, theirs, strict=True))
            for mine, theirs in ((self.snapshot, other.snapshot), (self.queue, other.queue),
                                 (self.anchor, other.anchor)))  # fmt: skip
        return Packed(self.t, np.asfortranarray(np.concatenate([self.plan, other.plan])),
                      np.concatenate([self.history, other.history]), np.concatenate([self.count, other.count]),
                      np.concatenate([self.st, other.st]), np.concatenate([self.sk, other.sk]), snapshot,
                      self.slow, queue, anchor)  # fmt: skip

    def plan_of(self, params: Params) -> EvasionPlan:
        from ._fast_period import PLAN

        fields = dict(zip(PLAN, self.plan.T, strict=True))  # (column-major: each column a contiguous view)
        for name in ("feasible", "follows_leader", "follows_own", "continues"):
            fields[name] = fields[name] != 0.0
        fields["reason"] = fields["reason"].astype(np.uint8)
        return EvasionPlan(**fields, params=params)

    def breach(self) -> Breach:
        return Breach(flags=self.sk[:, 5:10], first_s=self.st[:, 2])

    def state(self, params: Params, decision: Decision | None = None):
        """The :class:`~.core.ShieldState` (copies: later periods do not change it). With the period's ``decision``,
        its plan and breach record are the state's (as the stages share them)."""
        from .core import ShieldState

        p = dataclasses.replace(self, plan=self.plan.copy(order="F"), st=self.st.copy(), sk=self.sk.copy())
        last = None
        if p.snapshot is not None:
            cx, cv, bounds, nc = p.snapshot
            last = Snapshot(chain_x=cx, chain_v=cv, bounds=bounds, n_connected=nc, f_x=p.st[:, 3], f_v=p.st[:, 4],
                            f_limit=p.st[:, 5], plan_l1_decel=p.st[:, 6], plan_f_aggr=p.sk[:, 0].copy(),
                            active=p.sk[:, 4],
                            anchor=None if p.anchor is None else _unpack_anchor(p.anchor))  # fmt: skip
        belief = AssessmentState(history=self.history.copy(), count=self.count.copy(), aggressive=p.sk[:, 2],
                                 latched=p.sk[:, 1], first_collaborative_s=p.st[:, 1])  # fmt: skip
        if self.slow:
            from .policies import SlowState

            belief = SlowState(belief, p.st[:, 7], p.sk[:, 10], p.sk[:, 11])
        plan, breach = (p.plan_of(params), p.breach()) if decision is None else (decision.plan, decision.breach)
        return ShieldState(t=p.t, plan=plan, plan_t0=p.st[:, 0], plan_f_aggr=p.sk[:, 0], belief=belief, breach=breach,
                           completed=p.sk[:, 3], last=last, pending=_in_flight(self.queue))  # fmt: skip


def _queue_of(pending: InFlight | None, n: int) -> tuple | None:
    """:attr:`Packed.queue` of the commands in flight ``pending`` (``None``: none)."""
    if pending is None:
        return None
    d = len(pending.commands)
    knots, seg = np.zeros((n, d, KNOTS)), np.zeros((n, d, 2, KNOTS - 1))
    acc, flags = np.empty((n, d, 2)), np.zeros((n, d, 2), bool)
    for c, command in enumerate(pending.commands):
        acc[:, c, 0], acc[:, c, 1], flags[:, c, 0] = command.a_x, command.a_y, command.completing
        if command.rows.size:
            r = command.rows
            flags[r, c, 1] = True
            knots[r, c], seg[r, c, 0], seg[r, c, 1] = command.knots, command.ax_seg, command.ay_seg
    return knots, seg, acc, flags


def _in_flight(queue: tuple | None) -> InFlight | None:
    """The :class:`~.command.InFlight` of :attr:`Packed.queue` (copies)."""
    if queue is None:
        return None
    knots, seg, acc, flags = queue
    commands = []
    for c in range(knots.shape[1]):
        rows = np.flatnonzero(flags[:, c, 1])
        parts = (None, None, None) if not rows.size else (knots[rows, c], seg[rows, c, 0], seg[rows, c, 1])
        commands.append(Command(acc[:, c, 0].copy(), acc[:, c, 1].copy(), rows, *parts, flags[:, c, 0].copy()))
    return InFlight(commands=tuple(commands))


def _pack_anchor(anchor: Anchor, n: int) -> tuple:
    """An :class:`~.monitor.Anchor` as :attr:`Packed.anchor` (copies)."""
    from ._fast_period import ANCHOR_F

    f = np.empty((n, len(ANCHOR_F)))
    for j, name in enumerate(ANCHOR_F):
        f[:, j] = getattr(anchor, name)
    m = np.shape(anchor.chain_x)[1]
    chain = tuple(np.array(np.broadcast_to(getattr(anchor, name), (n, m)), float) for name in ("chain_x", "chain_v",
                                                                                              "bounds"))  # fmt: skip
    return (f, *chain, np.array(np.broadcast_to(anchor.n_connected, (n,)), np.int64))


def _unpack_anchor(packed: tuple) -> Anchor:
    """:attr:`Packed.anchor` as an :class:`~.monitor.Anchor` (copies)."""
    from ._fast_period import ANCHOR_F

    f, cx, cv, cb, nc = (a.copy() for a in packed)
    return Anchor(chain_x=cx, chain_v=cv, bounds=cb, n_connected=nc, **{name: f[:, j] for j, name in
                                                                        enumerate(ANCHOR_F)})  # fmt: skip


@functools.lru_cache(maxsize=16)
def _no_anchor(m: int) -> tuple:
    """The kernel's anchor arrays where there is none (no rows; inputs only: shared between calls)."""
    f = np.zeros((0, len(_period_module().ANCHOR_F)))
    return f, np.zeros((0, m)), np.zeros((0, m)), np.zeros((0, m)), np.zeros(0, np.int64)


def sense_arrays(situation, config: ShieldConfig, packed: Packed, own: tuple) -> tuple | None:
    """The kernel's ``sense`` tuple (:data:`._fast_period.SENSE`) for this period, or ``None`` where the
    configuration takes no sensing box into account and no anchor is held (the kernel's version without them).
    ``own``: the kernel's own-lane arrays. A box is the stages' ``observe``: every bound the situation gives, zeros
    for the others (:func:`~.realworld.worst_corners`), the chain's links at their corners where ``err_chain`` is
    given (:func:`~.stages.chain_analysis`); a new anchor where ``err_f`` or ``err_chain`` is
    (:func:`~.stages.remember`)."""
    s = situation
    boxed = config.sensing and s.has_errors
    if not boxed and packed.anchor is None:
        return None
    n, m = s.chain_x.shape
    k = own[0].shape[1]
    if boxed:
        err_f = np.zeros((n, 2)) if s.err_f is None else np.ascontiguousarray(s.err_f, float)
        err_chain = np.zeros((n, m, 2)) if s.err_chain is None else np.ascontiguousarray(s.err_chain, float)
        given = s.err_own is not None and config.own_lane  # (step's own-lane arrays are the situation's)
        err_own = np.ascontiguousarray(s.err_own, float) if given else np.zeros((n, k, 2))
        own_lane = config.own_lane and s.has_own_lane  # (stages.own_leader)
        modes = np.array([True, s.err_chain is not None, own_lane])
        corner = np.empty((n, m)), np.empty((n, m))
    else:
        err_f, err_chain, err_own = np.zeros((0, 2)), np.zeros((0, m, 2)), np.zeros((0, k, 2))
        modes, corner = np.zeros(3, bool), (np.zeros((0, m)), np.zeros((0, m)))
    held = _no_anchor(m) if packed.anchor is None else packed.anchor
    if boxed and (s.err_chain is not None or s.err_f is not None):
        new = (np.empty((n, held[0].shape[1])), np.empty((n, m)), np.empty((n, m)), np.empty((n, m)),
               np.empty(n, np.int64))
    else:
        new = _no_anchor(m)
    return (err_f, err_chain, err_own, modes, *corner, *held, *new)


@functools.cache
def _period_module():
    """:mod:`._fast_period` (imported on first use: it compiles; a function-level import costs a step ~1 µs)."""
    from . import _fast_period

    return _fast_period


@functools.lru_cache(maxsize=16)
def _no_own(n: int) -> tuple:
    """The kernel's own-lane arrays for ``n`` rows without an own-lane leader (inputs only: shared between calls)."""
    return np.full((n, 1), np.inf), np.zeros((n, 1)), np.zeros((n, 0)), np.zeros(n, np.int64)


@functools.lru_cache(maxsize=16)
def _no_queue(n: int) -> tuple:
    """The kernel's queue of commands in flight for ``n`` rows without a delay (empty: shared between calls)."""
    return np.zeros((n, 0, KNOTS)), np.zeros((n, 0, 2, KNOTS - 1)), np.zeros((n, 0, 2)), np.zeros((n, 0, 2), bool)


_NO_SEGS = np.zeros(0, np.int64)


@functools.lru_cache(maxsize=16)
def _paper_rule(n: int) -> np.ndarray:
    """The kernel's rule vectors for ``n`` rows under the paper's rule alone (an input only: shared between calls)."""
    return np.zeros((n, 1))


@functools.lru_cache(maxsize=64)
def period_constants(prm: Params, cfg: ShieldConfig) -> np.ndarray:
    """The kernel's parameter vector (its first entry, the period's time, is the caller's to set): the parameters,
    the tolerances and the settings it reads (both records are frozen, so the vector is built once per pair)."""
    out = np.array([0.0, prm.dt, prm.a_x_a, prm.a_x_d, prm.a_y_m, prm.y_safe, prm.p_m, prm.p_m_human, prm.y_boundary,
                    prm.lane_width, prm.others_decel, LATERAL_TOL_M, FEASIBILITY_TOL_M, TOL_M, cfg.assess_threshold,
                    float(cfg.monitor), max(own_completion_level(prm), prm.y_boundary), own_margin(prm),
                    float(cfg.assessment == "truth"), float(cfg.completion == "paper_evasion"),
                    float(cfg.assessment == "slow"), cfg.assess_delay_s, cfg.assess_miss, TIME_TOL_S,
                    prm.vehicle_length, prm.vehicle_width, delay_periods(cfg, prm) * prm.dt])  # fmt: skip
    out.flags.writeable = False
    return out


def step(packed: Packed, situation, proposal, params: Params, config: ShieldConfig, flags,
         chain=None, rule=None) -> tuple[Packed, Decision]:  # fmt: skip
    """One period compiled: ``(packed, situation, proposal) -> (packed', Decision)`` — :func:`.core.step`'s result
    for a period :func:`refusals` and :func:`situation_refusals` accept. ``proposal``: the checked ``(a_x, a_y)``
    arrays (:func:`.validation.batch_proposal`); ``flags``: the variant's ``(B, 3)`` flags
    (:func:`.policies.variant_flags`, stacked); ``chain``: ``(bounds, unsafe)``, the caller's
    :func:`~.stages.chain_analysis` of this situation, taken as given (as :func:`.core.step` takes it), or ``None``;
    ``rule``: the rows' decision rules (:func:`.rules.rule_table`), ``None`` for the paper's alone."""
    fp = _period_module()
    s, prm, cfg = situation, params, config
    n, m = s.chain_x.shape
    sf = np.empty((n, len(fp.SIT_F)))  # (the carried_* columns: the kernel's)
    sf[:, 0], sf[:, 1], sf[:, 2], sf[:, 3], sf[:, 4], sf[:, 5] = s.ego_x, s.ego_y, s.ego_vx, s.ego_vy, s.f_x, s.f_v
    sf[:, 6], sf[:, 7], sf[:, 8], sf[:, 9] = s.observed_f_speed, proposal[0], proposal[1], s.n_connected
    sb = np.empty((n, len(fp.SIT_B)), bool)
    sb[:, 0] = s.f_connected & s.f_collaborative
    sb[:, 1] = False if s.v2x_stale is None else s.v2x_stale
    sb[:, 2:5] = flags
    truth = cfg.assessment == "truth"
    if truth:
        if s.f_aggressive_truth is None:  # the stages' error (policies.TruthAssessment)
            raise ValueError("the 'truth' assessment needs Situation.f_aggressive_truth (a simulation study only)")
        sb[:, 5] = s.f_aggressive_truth
    else:
        sb[:, 5] = False
    prm_vec = period_constants(prm, cfg).copy()
    prm_vec[0] = s.t
    if cfg.own_lane and s.own_x is not None:
        k = s.own_x.shape[1]
        own = (np.ascontiguousarray(s.own_x), np.ascontiguousarray(s.own_v),
               np.ascontiguousarray(s.own_promise, float).reshape(n, k - 1), np.asarray(s.own_n_connected, np.int64))
    else:
        own = _no_own(n)
    queue = None if packed.queue is None else tuple(a.copy() for a in packed.queue)
    out = Packed(s.t + prm.dt, packed.plan.copy(order="F"), packed.history.copy(), packed.count.copy(),
                 packed.st.copy(), packed.sk.copy(), None, packed.slow, queue)  # fmt: skip
    if queue is None:
        queue, segs = _no_queue(n), _NO_SEGS
    else:  # (Command.piece: the knots less one where some row aborts, else one segment)
        segs = np.where(queue[3][:, :, 1].any(0), KNOTS - 1, 1).astype(np.int64)
    snap = packed.snapshot
    if snap is None:
        snap = (np.zeros((n, m)), np.zeros((n, m)), np.zeros((n, m)), np.zeros(n, np.int64))
    if chain is None:
        bounds, given_unsafe = np.empty((n, m)), np.zeros(0, np.bool_)
    else:
        bounds = np.array(np.broadcast_to(chain[0], (n, m)), float)
        given_unsafe = np.array(np.broadcast_to(chain[1], (n,)), np.bool_)
    behaviour = np.empty(n, np.int64)
    of, ob = np.empty((n, len(fp.OUT_F))), np.empty((n, len(fp.OUT_B)), bool)
    knots = np.empty((n, 5, 8))
    nc = np.asarray(s.n_connected, np.int64)
    rule = _paper_rule(n) if rule is None else rule
    sense = sense_arrays(s, cfg, packed, own)
    fp.period_kernel(prm_vec, sf, sb, rule, np.ascontiguousarray(s.chain_x), np.ascontiguousarray(s.chain_v),
                     np.ascontiguousarray(s.chain_promise, float).reshape(n, max(m - 1, 0)),
                     np.ascontiguousarray(s.chain_human, bool).reshape(n, max(m - 1, 0)), nc, *own, out.history,
                     out.count,
                     out.st, out.sk, out.plan, packed.snapshot is not None, *snap, bounds, given_unsafe, behaviour,
                     of, ob, knots, segs, *queue, *(() if sense is None else (sense,)))  # fmt: skip
    out.snapshot = (s.chain_x, s.chain_v, bounds, nc)
    if sense is not None:  # the snapshot at the analysis' corner; the anchor made, if any
        out.snapshot = (sense[4], sense[5], bounds, nc) if sense[3][0] else out.snapshot
        out.anchor = sense[11:] if len(sense[11]) else None
    rows = ob[:, 4].nonzero()[0]  # the aborts on the held plan (an RSS response is a constant command)
    if rows.size:
        k = knots[rows]
        abort = (rows, k[:, 0], k[:, 1], k[:, 2], k[:, 3], k[:, 4])
    else:
        abort = (rows, None, None, None, None, None)
    decision = Decision(
        behaviour=behaviour, a_x=of[:, 0], a_y=of[:, 1], completing=ob[:, 0], invalid=ob[:, 1],
        _plan=functools.partial(out.plan_of, prm), plan_t0=out.st[:, 0].copy(), l1_decel=of[:, 4],
        f_aggressive=ob[:, 2], breach=Breach(flags=out.sk[:, 5:10].copy(), first_s=out.st[:, 2].copy()),
        nominal_x=of[:, 2], nominal_y=of[:, 3], _abort=abort,
    )  # fmt: skip
    return out, decision
