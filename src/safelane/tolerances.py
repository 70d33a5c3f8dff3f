"""Every numerical tolerance of the package, named once (the modules that compare against one import it from here).

All of them absorb float64 round-off of exact closed forms and of times on the control-period grid; none is a
physical margin (those are :class:`~safelane.params.Params` fields: ``p_m``, ``y_safe``, …).

=====================  ========  ==========================================================================
name                   value     what it absorbs
=====================  ========  ==========================================================================
``DIST_TOL_M``         1e-9 m    a gap within this of its margin counts as satisfied (the safety analysis'
                                 feasibility, the lateral intrusion beyond ``y_s``, the ``p_m`` and overlap
                                 checks of every referee)
``TIME_TOL_S``         1e-9 s    times on the ``dt`` grid (``0.1 · 7`` is not ``0.7`` in float64): an instant
                                 this close to a switch or a deadline counts as reached
``SPEED_TOL_MPS``      1e-9 m/s  speeds this close count as equal (a speed braked to zero)
``ACCEL_TOL_MPS2``     1e-9 m/s² an acceleration this far outside a limit counts as inside (proposals); the
                                 closed-form braking bounds are applied this far on the safe side
``SETTING_SLACK``      1e-12     comparisons between settings (a horizon against one period, a profile's
                                 steps and accelerations against their ranges)
``MONITOR_TOL_M``      1e-7 m    the assumption monitor's comparison of a state against the worst case it
                                 predicted (the prediction is integrated in closed form from an earlier state)
=====================  ========  ==========================================================================
"""

from __future__ import annotations

DIST_TOL_M = 1e-9
TIME_TOL_S = 1e-9
SPEED_TOL_MPS = 1e-9
ACCEL_TOL_MPS2 = 1e-9
SETTING_SLACK = 1e-12
MONITOR_TOL_M = 1e-7

__all__ = ["ACCEL_TOL_MPS2", "DIST_TOL_M", "MONITOR_TOL_M", "SETTING_SLACK", "SPEED_TOL_MPS", "TIME_TOL_S"]
