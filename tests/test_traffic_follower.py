"""Which vehicle is F of a changer in the traffic co-simulation (safelane.traffic.equipped, docs/traffic.md): the
nearest vehicle behind in the target lane, at the highest speed of the vehicles from it back to the nearest one that
stays in that lane — a changer still changing lanes is there only for now. The case is the p = 1 collision of the
hour-long sweep (t = 3884.2 s, docs/traffic.md): ``cav.5159`` changed left with ``cav.5162`` — itself changing
left, 6 m behind — as its F, ``cav.5162`` aborted and went back, and ``cav.5173``, 28 m/s in the target lane, ran
into ``cav.5159`` (10 m/s). And the cut-in rule of the blame: an entry within the safe distance of any vehicle
behind, not only the nearest."""

from __future__ import annotations

import numpy as np
import pytest

from safelane.shield.rows import take_rows
from safelane.traffic.demand import lane_y
from test_traffic_others import PRM, changes, fleet


def _scene(c_done=np.nan, c_ret=False):
    f = fleet([
        ("cav.a", 1490.0, lane_y(0), 28.4, 0.0),  # lane 0, driven by SUMO (not a changer)
        ("cav.c", 1547.0, lane_y(1) + 1.3, 10.6, 0.0),  # changing left too, its body across the line into lane 0
        ("cav.b", 1553.0, lane_y(1), 10.0, 0.0),  # starts changing left (target lane 0)
        ("human.l1", 1620.0, lane_y(0), 27.0, 0.0),
    ])  # fmt: skip
    ch, rows = changes(f, [("cav.c", 1, 1.0, 1.3, 0.0, 0.0, c_ret), ("cav.b", 1, 1.0, 0.0, 0.0, 0.0, False)])
    ch.t_done[0] = c_done
    s, _ = ch.situation(f, f.x.copy(), rows, 5.0)
    return s


def test_f_is_the_nearest_at_the_speed_of_the_fastest_back_to_one_that_stays():
    s = _scene()
    # cav.b's F: at cav.c's position (6 m behind, across the line, still changing) with cav.a's speed (63 m behind,
    # in lane 0, staying)
    assert (s.f_x[1], s.f_v[1]) == (1547.0, 28.4)
    assert s.f_connected[1]  # cav.c is equipped


def test_a_changer_that_completed_into_the_lane_stays_and_one_returning_from_it_does_not():
    done = _scene(c_done=4.0)  # cav.c completed its change into lane 0: it stays there, and it is F as it is
    assert (done.f_x[1], done.f_v[1]) == (1547.0, 10.6)
    back = _scene(c_ret=True)  # cav.c aborted and returns to lane 1: it leaves lane 0
    assert (back.f_x[1], back.f_v[1]) == (1547.0, 28.4)


@pytest.mark.parametrize("c_aborts_at", [0.5, 1.5, None])
def test_the_change_keeps_p_m_to_both_followers_when_the_one_between_leaves(c_aborts_at):
    """The traced case, closed loop: ``cav.b`` (10 m/s) changes left under the shield with the reckless proposal
    (straight across), its situation rebuilt every period from the moving fleet by the traffic code; ``cav.c``,
    6 m behind at 10.6 m/s across the line, goes on into lane 0 or, at ``c_aborts_at`` seconds, returns to lane 1
    at 1.5 m/s²; ``cav.a`` comes at 28.4 m/s in lane 0. Whenever ``cav.b``'s body is in lane 0 it keeps ``p_m``
    (centre to centre, the shield's convention) to each vehicle of lane 0 behind it, over 8 s (the motion exact
    within each period, checked at 10 instants)."""
    from safelane.shield import Shield

    dt, w = PRM.dt, PRM.lane_width
    shield = Shield(PRM)
    xa, xc, yc, vyc, xb, yb, vxb, vyb, xl = 1490.0, 1547.0, 1.3, 0.0, 1553.0, 0.0, 10.0, 0.0, 1620.0
    ret, worst, entered = False, np.inf, False
    for k in range(80):
        t = 5.0 + k * dt
        if c_aborts_at is not None and k * dt >= c_aborts_at:
            ret = True
        f = fleet([("cav.a", xa, lane_y(0), 28.4, 0.0), ("cav.c", xc, lane_y(1) + yc, 10.6, vyc),
                   ("cav.b", xb, lane_y(1) + yb, vxb, vyb), ("human.l1", xl, lane_y(0), 27.0, 0.0)])  # fmt: skip
        ch, rows = changes(f, [("cav.c", 1, 1.0, yc, vyc, 0.0, ret), ("cav.b", 1, 1.0, yb, vyb, 0.0, False)])
        ch.others = False
        s, _ = ch.situation(f, f.x.copy(), rows, t)
        one = take_rows(s, np.array([1]))
        if k == 0:
            shield.reset(one)
        d = shield.step(one, (np.array([1.0]), np.array([1.5])))
        ax, ay = float(d.a_x[0]), float(d.a_y[0])
        ayc = -1.5 if ret else (0.5 if yc < w else -0.5 * vyc / dt)  # cav.c: on across, or back to lane 1
        for tau in np.linspace(0.0, dt, 11)[1:]:
            y = yb + vyb * tau + 0.5 * ay * tau * tau
            if y > PRM.y_safe:  # cav.b's body in lane 0
                entered = True
                x = xb + vxb * tau + 0.5 * ax * tau * tau
                behind = [xa + 28.4 * tau]
                if yc + vyc * tau + 0.5 * ayc * tau * tau > PRM.y_safe:  # cav.c's body in lane 0 too
                    behind.append(xc + 10.6 * tau)
                worst = min([worst] + [x - xr for xr in behind if xr < x])
        xb, vxb = xb + vxb * dt + 0.5 * ax * dt * dt, max(vxb + ax * dt, 0.0)
        yb, vyb = yb + vyb * dt + 0.5 * ay * dt * dt, vyb + ay * dt
        yc, vyc = yc + vyc * dt + 0.5 * ayc * dt * dt, vyc + ayc * dt
        xa, xc, xl = xa + 28.4 * dt, xc + 10.6 * dt, xl + 27.0 * dt
    assert worst >= PRM.p_m - 1e-6, (worst, PRM.p_m)
    assert entered or c_aborts_at is None  # it did enter where cav.c could leave (the test exercises the rule)


def test_an_entry_within_the_safe_distance_of_a_vehicle_behind_the_nearest_is_its_cut_in():
    """RSS: a vehicle enters a lane at the safe distance of each vehicle of that lane. At 3882.4 s ``cav.5159``'s
    body entered lane 0 with ``cav.5162`` (straddling) nearest behind and ``cav.5173`` 30 m behind at 28.1 vs
    9.7 m/s (safe distance 0.5·28.1 + 28.1²/9 − 9.7²/16 = 96 m); ``cav.5173`` hit it 1.8 s later: ``cav.5159`` is
    responsible (the rule took the nearest follower only and named ``cav.5173``)."""
    from safelane.traffic import measures

    w, length = PRM.vehicle_width, PRM.vehicle_length
    before = fleet([("cav.5173", 1529.5, lane_y(0), 28.13, 0.0), ("cav.5162", 1549.8, lane_y(1) + 1.28, 10.83, 0.0),
                    ("cav.5159", 1566.6, lane_y(1) + 0.80, 9.71, 0.0), ("human.far", 1300.0, lane_y(0), 28.0, 0.0)])
    after = fleet([("cav.5173", 1532.4, lane_y(0), 28.08, 0.0), ("cav.5162", 1550.9, lane_y(1) + 1.29, 11.08, 0.0),
                   ("cav.5159", 1567.5, lane_y(1) + 0.88, 9.70, 0.0), ("human.far", 1302.8, lane_y(0), 28.0, 0.0)])
    prev: dict[str, int] = {}
    assert measures.lane_entries(3882.3, before, prev, length, w) == []
    entries = measures.lane_entries(3882.4, after, prev, length, w)
    got = {(e["vid"], e["follower"]): e["gap_m"] for e in entries}
    assert set(got) == {("cav.5159", "cav.5162"), ("cav.5159", "cav.5173")}  # not human.far (229 m back)
    assert got[("cav.5159", "cav.5173")] == pytest.approx(1567.5 - 1532.4 - length)
    assert float(measures.safe_distance(28.08, 9.70)) == pytest.approx(0.5 * 28.08 + 28.08**2 / 9 - 9.70**2 / 16)
    crash = {"t": 3884.2, "collider": "cav.5173", "victim": "cav.5159", "type": "collision"}
    assert measures.blame([crash], entries)[0]["responsible"] == "cav.5159"
    # the nearest follower only (the rule before): cav.5173 responsible
    nearest = [e for e in entries if e["follower"] == "cav.5162"]
    assert measures.blame([crash], nearest)[0]["responsible"] == "cav.5173"
