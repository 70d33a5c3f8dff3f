"""Checking and resolving the arguments of :func:`safelane.sim.simulate` (and the settings of every run).

Every bad argument raises :class:`~safelane.errors.InputError` (a ``ValueError``) with one line naming the
argument, the value and what is allowed. Where a user would pass a name, a name works: ``nominal="mlp"``,
``preset="paper"``; ``params``, ``config`` and ``scenario`` also take plain mappings (validated like files).

The seeding scheme lives here too (:func:`cell_rng`): the initial states of an experiment cell are drawn from a
generator keyed by the run seed and the cell's settings only, so ``simulate``, ``run_cells`` and ``safelane
reproduce`` give the same scenarios — hence the same numbers — for the same cell and seed.
"""

from __future__ import annotations

import numbers
import os
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..config import validate_model
from ..errors import InputError
from ..params import Params
from ..tolerances import SETTING_SLACK
from .config import SimConfig

_SLACK = SETTING_SLACK


def cell_rng(
    seed: int, n_leaders: int, decel: float, p_v: float = 0.0, penetration: float | None = None
) -> np.random.Generator:
    """The generator of one cell's initial states: keyed by the run seed and the cell's scenario settings only,
    so a cell gives the same numbers whichever grid (or entry point) runs it, and every planner variant sees
    the same scenarios (common random numbers: planner differences are not sampling noise)."""
    pen = -1 if penetration is None else round(penetration * 1e6)
    return np.random.default_rng([seed, n_leaders, round(decel * 1e6), round(p_v * 1e6), pen + 1])


def _is_int(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool | np.bool_)


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _got(value) -> str:
    return f"{value!r} ({type(value).__name__})"


def check_cell_args(planner, n_leaders, decel, samples, seed, p_v) -> None:
    """Types and ranges of the cell arguments of ``simulate``."""
    from ..planners.variants import VARIANT_NAMES, get_variant

    if not isinstance(planner, str):
        raise InputError(f"planner must be a variant name ({', '.join(VARIANT_NAMES)}); got {_got(planner)}", "planner")
    get_variant(planner)
    if not _is_int(n_leaders) or n_leaders < 0:
        raise InputError(f"n_leaders must be a non-negative integer; got {_got(n_leaders)}", "n_leaders")
    if not _is_real(decel) or not np.isfinite(decel) or decel <= 0:
        raise InputError(f"decel (a_x_N+1_d) must be a positive finite number [m/s²]; got {_got(decel)}", "decel")
    if not _is_int(samples) or samples < 1:
        raise InputError(f"samples must be a positive integer; got {_got(samples)}", "samples")
    if not _is_int(seed) or seed < 0:
        raise InputError(f"seed must be a non-negative integer; got {_got(seed)}", "seed")
    if not _is_real(p_v) or not 0.0 <= p_v <= 1.0:
        raise InputError(f"p_v (promise-violation rate) must lie in [0, 1]; got {_got(p_v)}", "p_v")


def as_model(cls, value, name: str):
    """``None``, an instance of ``cls`` or a mapping of its fields → an instance (or ``None``)."""
    if value is None or isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        return validate_model(cls, dict(value), name)
    raise InputError(f"{name} must be a {cls.__name__} or a mapping of its fields; got {_got(value)}", name)


def as_nominal(value):
    """``None``, a registered name (``"expert"``, ``"mlp"``, ``"mlp_paper"``, ``"teacher"``), the path of a model
    file (``.npz`` as ``safelane train`` writes it, ``.onnx`` as ``safelane export-onnx`` does;
    :func:`~safelane.planners.registry.load_nominal`) or a planner callable (with a preset, :func:`preset_nominal`
    reads ``"expert"`` as the preset's rule-based planner)."""
    if value is None:
        return None
    if isinstance(value, str | os.PathLike):
        from ..planners.registry import load_nominal

        try:
            return load_nominal(value)
        except ValueError as exc:
            raise InputError(str(exc), "nominal") from exc
    if not callable(value):
        raise InputError(
            "nominal must be a registered name, the path of a .npz/.onnx model or a planner called as "
            f"planner(obs, params); got {_got(value)}",
            "nominal",
        )
    return value


def preset_nominal(chosen, nominal):
    """The nominal planner of a run under the preset ``chosen`` (or ``None``): ``"expert"`` is the preset's
    rule-based planner with its gains (what its network imitates), ``None`` the preset's own (its network, if it
    names one), anything else as :func:`as_nominal` reads it. Another registered network than the one the preset
    names warns (:func:`network_mismatch`): its numbers are not the preset's."""
    if chosen is not None and isinstance(nominal, str) and nominal == "expert":
        return chosen.expert()
    mismatch = network_mismatch(chosen, nominal)
    if mismatch:
        warnings.warn(mismatch, UserWarning, stacklevel=4)  # the caller of simulate()
    nominal = as_nominal(nominal)
    return chosen.nominal() if nominal is None and chosen is not None else nominal


def network_mismatch(chosen, nominal) -> str | None:
    """The warning for a registered network other than the one the preset ``chosen`` names (``paper`` with
    ``nominal="mlp"``: ``mlp`` learnt the default world, the preset's numbers come from ``mlp_paper``), else
    ``None``. ``"expert"`` (the preset's rule-based planner), a model file and a planner object are deliberate
    choices and do not warn."""
    from ..planners.registry import NOMINAL_PLANNERS

    network = getattr(chosen, "network", None)
    if network is None or not isinstance(nominal, str) or nominal in ("expert", network):
        return None
    if nominal not in NOMINAL_PLANNERS:
        return None
    return (f"nominal planner {nominal!r} is not the network of preset {chosen.name!r} ({network!r}), which its "
            f"published numbers use; leave nominal / --nominal out for {network!r}")  # fmt: skip


def nominal_label(chosen, nominal) -> str:
    """What a run's records (``run.json``, :meth:`SimResult.summary`, the printed summary) call its nominal planner,
    given the preset ``chosen`` (or ``None``) and the ``nominal`` argument as the user gave it."""
    if chosen is not None and (nominal == "expert" or (nominal is None and chosen.network is None)):
        return "expert (preset gains)"
    if nominal is None:
        return chosen.network if chosen is not None else "expert"
    if isinstance(nominal, str | os.PathLike):
        return str(nominal)
    return getattr(nominal, "__name__", type(nominal).__name__)


def resolve(preset, params, config, scenario, nominal):
    """The run's ``(params, config, scenario, nominal, labels)``: explicit arguments first, then the preset's parts;
    ``labels``: the preset's name (or ``None``) and :func:`nominal_label`, as :class:`~.results.SimResult` records
    them."""
    from .scenario import ScenarioConfig

    chosen = None
    if preset is not None:
        from .preset import Preset, load_preset

        if not isinstance(preset, str | Path | Preset):
            raise InputError(f"preset must be a preset name, a path or a Preset; got {_got(preset)}", "preset")
        chosen = load_preset(preset)
    params = as_model(Params, params, "params")
    config = as_model(SimConfig, config, "config")
    scenario = as_model(ScenarioConfig, scenario, "scenario")
    labels = {"preset": None if chosen is None else chosen.name, "nominal": nominal_label(chosen, nominal)}
    nominal = preset_nominal(chosen, nominal)
    if chosen is not None:
        params = chosen.params if params is None else params
        config = chosen.sim if config is None else config
    params = Params() if params is None else params
    check_settings(params, config or SimConfig(), scenario)
    return params, config, scenario, nominal, labels


def check_settings(params: Params, config: SimConfig, scenario=None) -> None:
    """Cross-checks between the settings of a run (each one is valid alone)."""
    if config.horizon_s < params.dt - _SLACK:
        raise InputError(
            f"config.horizon_s={config.horizon_s} is shorter than one control period params.dt={params.dt}: "
            "nothing would be simulated",
            "config.horizon_s",
        )
    if scenario is None:
        return
    if scenario.promise_decel > params.a_x_d + _SLACK:
        raise InputError(
            f"scenario.promise_decel={scenario.promise_decel} exceeds params.a_x_d={params.a_x_d}: a promise beyond "
            "the mechanical limit (the V2X layer rejects such messages)",
            "scenario.promise_decel",
        )
    if scenario.promise_accel > params.a_x_a + _SLACK:
        raise InputError(
            f"scenario.promise_accel={scenario.promise_accel} exceeds params.a_x_a={params.a_x_a}: a promise beyond "
            "the mechanical limit (the V2X layer rejects such messages)",
            "scenario.promise_accel",
        )
    if scenario.gap[0] < params.vehicle_length:
        # Allowed (tests use it to check that overlaps are reported), but every such scenario starts in a crash.
        warnings.warn(
            f"scenario.gap lower bound {scenario.gap[0]} m is below params.vehicle_length={params.vehicle_length} m: "
            "initial vehicles overlap and those scenarios start in collision",
            stacklevel=4,
        )


def check_scenario_ranges(cfg):
    """``ScenarioConfig`` validator: ranges ``(lo, hi)`` in order and physically possible."""
    lo, hi = cfg.ego_speed
    if not 0.0 <= lo <= hi:
        raise ValueError(f"ego_speed=({lo}, {hi}) must satisfy 0 <= lo <= hi [m/s]")
    lo, hi = cfg.gap
    if not 0.0 < lo <= hi:
        raise ValueError(f"gap=({lo}, {hi}) must satisfy 0 < lo <= hi [m]")
    return cfg
