"""Every claim of ``experiments.claims`` on a case where it holds and on cases where it fails — one per condition
the claim combines, so that dropping or weakening any one of them (``and`` → ``or``, a bound moved) fails a test."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from safelane.experiments.claims import CONSIDERABLY_MIN, FOLLOWER_RATIO, RELATIVELY_HIGH, SLIGHTLY_MAX, check_claims
from safelane.sim.metrics import wilson_interval


def cell(planner, n, decel, p_v, rate, samples=1000, collisions=0, violations=0) -> dict:
    """One summary row with ``rate`` of ``samples`` successes and the Wilson intervals the runner would give."""
    rec = {"planner": planner, "n_leaders": n, "decel": decel, "p_v": p_v, "penetration": 1.0, "samples": samples}
    for name, count in (
        ("success", round(rate * samples)),
        ("collision", collisions),
        ("safety_violation", violations),
    ):
        lo, hi = wilson_interval(count, samples)
        rec |= {f"{name}_rate": count / samples, f"{name}_lo": float(lo), f"{name}_hi": float(hi)}
    return rec


def frame(*rows: dict) -> pd.DataFrame:
    return pd.DataFrame(list(rows))


def verdict(key: str, summaries: dict, trace: pd.DataFrame | None = None):
    return {c.key: c for c in check_claims(summaries, trace)}[key].holds


# -- zero collisions ----------------------------------------------------------------------------------------------
def test_zero_collisions_holds_with_none_at_p_v_zero_and_fails_with_one():
    clean = frame(cell("CV_all", 10, 4.0, 0.0, 0.9, violations=3), cell("CV_all", 10, 4.0, 0.5, 0.6, collisions=7))
    assert verdict("zero_collisions", {"fig6_violation": clean}) is True
    dirty = frame(cell("CV_all", 10, 4.0, 0.0, 0.9, collisions=1))
    assert verdict("zero_collisions", {"table1": dirty}) is False
    assert verdict("zero_collisions", {}) is None


# -- ordering -----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("better", "worse"), [("CV_all", "CV_follow"), ("CV_follow", "CV_none"),
                                               ("CV_none", "No_agg_assess")])  # fmt: skip
def test_ordering_holds_in_order_and_fails_on_each_clear_reversal(better, worse):
    ordered = frame(cell(better, 5, 4.0, 0.0, 0.8), cell(worse, 5, 4.0, 0.0, 0.6))
    assert verdict("ordering", {"fig4_n5": ordered}) is True
    reversed_ = frame(cell(better, 5, 4.0, 0.0, 0.6), cell(worse, 5, 4.0, 0.0, 0.8))
    assert verdict("ordering", {"fig4_n5": reversed_}) is False
    within_noise = frame(cell(better, 5, 4.0, 0.0, 0.58, samples=100), cell(worse, 5, 4.0, 0.0, 0.6, samples=100))
    assert verdict("ordering", {"fig4_n5": within_noise}) is True


# -- the information claims -----------------------------------------------------------------------------------
def _pair(better, worse, rate_better, rate_worse, samples=1000, n=5) -> pd.DataFrame:
    return frame(cell(better, n, 4.0, 0.0, rate_better, samples), cell(worse, n, 4.0, 0.0, rate_worse, samples))


def test_follower_information_needs_a_clear_and_considerable_gain():
    assert verdict("follower_information", {"fig4_n5": _pair("CV_follow", "CV_none", 0.9, 0.6)}) is True
    # In the published Table 1 cells too (N = 1 or 10).
    assert verdict("follower_information", {"table1": _pair("CV_follow", "CV_none", 0.9, 0.6, n=10)}) is True
    # Clear but small (intervals apart at 100,000 samples, yet less than CONSIDERABLY_MIN).
    small = _pair("CV_follow", "CV_none", 0.62, 0.62 - CONSIDERABLY_MIN / 2, samples=100_000)
    assert verdict("follower_information", {"fig4_n5": small}) is False
    # Large but not clear (20 samples).
    noisy = _pair("CV_follow", "CV_none", 0.6, 0.5, samples=20)
    assert verdict("follower_information", {"fig4_n5": noisy}) is False
    assert verdict("follower_information", {}) is None


def test_chain_information_is_slight_neither_clearly_below_nor_large():
    assert verdict("chain_information", {"fig4_n5": _pair("CV_all", "CV_follow", 0.62, 0.6)}) is True
    large = _pair("CV_all", "CV_follow", 0.6 + 2 * SLIGHTLY_MAX, 0.6)
    assert verdict("chain_information", {"fig4_n5": large}) is False
    clearly_below = _pair("CV_all", "CV_follow", 0.6, 0.61, samples=200_000)
    assert verdict("chain_information", {"fig4_n5": clearly_below}) is False
    assert verdict("chain_information", {}) is None


def _table1(follower_effect: float, chain_effect: float) -> pd.DataFrame:
    """Published Table 1 cells (N = 1, 10; two decelerations) with the given per-cell effects."""
    rows = []
    for n in (1, 10):
        for d in (2.0, 4.0):
            none = 0.5
            rows += [cell("CV_none", n, d, 0.0, none), cell("CV_follow", n, d, 0.0, none + follower_effect),
                     cell("CV_all", n, d, 0.0, none + follower_effect + chain_effect)]  # fmt: skip
    return frame(*rows)


def test_conclusion_1_needs_a_positive_follower_effect_several_times_the_chain_effect():
    assert verdict("conclusion_1", {"table1": _table1(0.2, 0.2 / (2 * FOLLOWER_RATIO))}) is True
    assert verdict("conclusion_1", {"table1": _table1(0.2, 0.2 / (0.5 * FOLLOWER_RATIO))}) is False
    # A negative follower effect fails even where it is "several times" a more negative chain effect.
    assert verdict("conclusion_1", {"table1": _table1(-0.05, -0.1)}) is False
    assert verdict("conclusion_1", {}) is None


# -- trends -------------------------------------------------------------------------------------------------------
def test_success_falling_with_decel_holds_and_fails_on_a_clear_rise():
    falling = frame(cell("CV_all", 5, 2.0, 0.0, 0.9), cell("CV_all", 5, 6.0, 0.0, 0.3))
    assert verdict("falls_with_decel", {"fig4_n5": falling}) is True
    rising = frame(cell("CV_all", 5, 2.0, 0.0, 0.3), cell("CV_all", 5, 6.0, 0.0, 0.9))
    assert verdict("falls_with_decel", {"fig4_n5": rising}) is False


def test_success_rising_with_n_holds_and_fails_on_a_clear_fall():
    rising = frame(cell("CV_all", 1, 4.0, 0.0, 0.3), cell("CV_all", 10, 4.0, 0.0, 0.9))
    assert verdict("rises_with_n", {"leaders": rising}) is True
    falling = frame(cell("CV_all", 1, 4.0, 0.0, 0.9), cell("CV_all", 10, 4.0, 0.0, 0.3))
    assert verdict("rises_with_n", {"leaders": falling}) is False


# -- robustness to promise violations ------------------------------------------------------------------------------
def _fig6(low_success=0.9, low_collisions=0, corner_success=0.4, corner_collisions=12, base_collisions=0):
    """A Fig. 6 grid: p_v in {0, 0.2, 0.5}, a in {2, 4, 6}; the low corner (p_v <= 0.2, a < 5) at
    ``low_success``; the high corner (p_v = 0.5, a = 6) at ``corner_*``; the base (p_v = 0, a = 2) with
    ``base_collisions``."""
    rows = []
    for pv in (0.0, 0.2, 0.5):
        for d in (2.0, 4.0, 6.0):
            if (pv, d) == (0.5, 6.0):
                rows.append(cell("CV_all", 10, d, pv, corner_success, collisions=corner_collisions))
            elif pv <= 0.2 and d < 5:
                base = (pv, d) == (0.0, 2.0)
                rows.append(cell("CV_all", 10, d, pv, 0.95 if base else low_success,
                                 collisions=base_collisions if base else low_collisions))  # fmt: skip
            else:
                rows.append(cell("CV_all", 10, d, pv, 0.7))
    return {"fig6_violation": frame(*rows)}


def test_robust_low_pv_needs_no_collision_and_relatively_high_success():
    assert verdict("robust_low_pv", _fig6()) is True
    assert verdict("robust_low_pv", _fig6(low_collisions=1)) is False
    assert verdict("robust_low_pv", _fig6(low_success=RELATIVELY_HIGH - 0.05)) is False
    assert verdict("robust_low_pv", {}) is None


def test_degrades_high_pv_needs_both_lower_success_and_more_collisions():
    # Kills `and` -> `or` in degrades_high_pv: each half alone must not make the claim hold.
    assert verdict("degrades_high_pv", _fig6()) is True
    assert verdict("degrades_high_pv", _fig6(corner_collisions=0)) is False  # lower success, no more collisions
    assert verdict("degrades_high_pv", _fig6(corner_success=0.95)) is False  # more collisions, same success
    assert verdict("degrades_high_pv", _fig6(corner_collisions=3, base_collisions=3)) is False
    assert verdict("degrades_high_pv", {}) is None


# -- Fig. 5 --------------------------------------------------------------------------------------------------------
def _trace(all_done_s=3.0, peak_s=3.0, follow_extra_s=1.0, none_offset_m=0.0, others_complete=False) -> pd.DataFrame:
    """A synthetic ``fig5_example`` trace (0.1 s steps to 8 s): CV_all moves over and completes at
    ``all_done_s``; the others rise to a peak at ``peak_s`` (CV_follow staying ``follow_extra_s`` longer at it)
    and return; No_agg_assess is CV_none shifted by ``none_offset_m``."""
    t = np.round(np.arange(0.0, 8.0, 0.1), 10)
    rows = []

    def add(planner, y, completed):
        rows.extend({"planner": planner, "t": ti, "ego_y": yi, "completed": ci}
                    for ti, yi, ci in zip(t, y, completed, strict=True))  # fmt: skip

    y_all = np.clip(t / all_done_s, 0.0, 1.0) * 3.5
    add("CV_all", y_all, t >= all_done_s)

    def bump(hold):
        up = np.clip(t / peak_s, 0.0, 1.0) * 1.5
        down = np.clip(1.0 - (t - peak_s - hold), 0.0, 1.0) * 1.5
        return np.where(t <= peak_s, up, np.where(t <= peak_s + hold, 1.5, down))

    add("CV_follow", bump(follow_extra_s), np.full(t.shape, others_complete))
    add("CV_none", bump(0.0), np.zeros(t.shape, bool))
    add("No_agg_assess", bump(0.0) + none_offset_m, np.zeros(t.shape, bool))
    return pd.DataFrame(rows)


@pytest.mark.parametrize(
    ("key", "failing"),
    [
        ("fig5_cv_all_3s", {"all_done_s": 5.0}),
        ("fig5_turn_back_3s", {"peak_s": 5.0}),
        ("fig5_turn_back_3s", {"others_complete": True}),
        ("fig5_follow_longer", {"follow_extra_s": 0.0}),
        ("fig5_none_coincide", {"none_offset_m": 0.05}),
    ],
)
def test_fig5_claims_hold_on_the_described_example_and_fail_off_it(key, failing):
    assert verdict(key, {}, _trace()) is True
    assert verdict(key, {}, _trace(**failing)) is False
    assert verdict(key, {}, None) is None
