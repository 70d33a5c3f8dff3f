"""The shield in other simulators: :mod:`.highway` (highway-env, extra ``highway``) and :mod:`.sumo` (libsumo, extra
``sumo``). Each adapter reads the host's vehicles, builds a :class:`~safelane.shield.Situation` and filters the ego's
action through a :class:`~safelane.shield.Shield`; the host's own collision accounting is the referee. Nothing here is
imported by ``import safelane``: the hosts import lazily, with an install hint where they are missing.
"""
