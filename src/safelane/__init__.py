"""safelane — safe lane changing for connected autonomous vehicles in mixed traffic."""

from .params import Params
from .v2x import V2XMessage, chain_arrays, leader_arrays

__version__ = "0.1.0"

__all__ = ["Params", "V2XMessage", "__version__", "chain_arrays", "leader_arrays"]
