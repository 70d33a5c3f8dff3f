"""safelane — safe lane changing for connected autonomous vehicles in mixed traffic.

``safelane.Params`` and the V2X messages load eagerly; the heavier entry points (``simulate``,
``simulate_batch``, the ``safety``/``sim``/``planners``/``experiments`` packages) load on first use.
"""

from importlib import import_module

from .params import Params
from .v2x import V2XMessage, chain_arrays, leader_arrays

__version__ = "0.1.0"

_LAZY = {
    "simulate": ("safelane.sim", "simulate"),
    "simulate_batch": ("safelane.sim", "simulate_batch"),
    "SimConfig": ("safelane.sim", "SimConfig"),
    "load_preset": ("safelane.sim.preset", "load_preset"),
    "Preset": ("safelane.sim.preset", "Preset"),
    "InputError": ("safelane.errors", "InputError"),
    "safety": ("safelane.safety", None),
    "sim": ("safelane.sim", None),
    "planners": ("safelane.planners", None),
    "experiments": ("safelane.experiments", None),
}


def __getattr__(name: str):
    if name in _LAZY:
        module, attr = _LAZY[name]
        mod = import_module(module)
        return mod if attr is None else getattr(mod, attr)
    raise AttributeError(f"module 'safelane' has no attribute {name!r}")


__all__ = ["InputError", "Params", "Preset", "SimConfig", "V2XMessage", "__version__", "chain_arrays",
           "leader_arrays", "load_preset", "simulate", "simulate_batch"]
