"""safelane — safe lane changing for connected autonomous vehicles in mixed traffic."""

from .params import Params

__version__ = "0.1.0"

__all__ = ["Params", "__version__"]
