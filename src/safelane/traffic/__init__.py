"""Traffic-level co-simulation in SUMO: a motorway merge, SUMO's human drivers and a share of equipped vehicles
whose lane changes run under the shield, with network measures (docs/traffic.md). Needs libsumo (extra ``sumo``);
nothing here imports it until a run starts."""

from .demand import SSM_THRESHOLDS, Demand, net_file
from .measures import blame, safe_distance
from .run import CELL_COLUMNS, cells, run_cell, sweep

__all__ = ["CELL_COLUMNS", "SSM_THRESHOLDS", "Demand", "blame", "cells", "net_file", "run_cell", "safe_distance",
           "sweep"]
