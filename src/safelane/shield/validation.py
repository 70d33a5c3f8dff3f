"""The checks of :class:`~safelane.shield.Shield`'s inputs, at construction and at every call.

A bad argument raises :class:`~safelane.errors.InputError` (a ``ValueError``) with one line naming the argument,
the value and what is allowed — the style of ``--params`` and ``simulate`` — at the call that received it, never
later from deep inside the analysis. ``Shield("paper")`` is the classic mistake: a preset's name where the
parameters go; the error names :meth:`Shield.from_preset <safelane.shield.Shield.from_preset>`, which builds a
shield from a preset.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping

import numpy as np

from ..config import validate_model
from ..errors import InputError
from ..params import Params


def _got(value) -> str:
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({type(value).__name__})"


def shield_params(params) -> Params:
    """``None`` (the defaults), a :class:`~safelane.Params` or a mapping of its fields → a ``Params``."""
    if params is None:
        return Params()
    if isinstance(params, Params):
        return params
    if isinstance(params, Mapping):
        return validate_model(Params, dict(params), "Shield params")
    hint = ""
    if isinstance(params, str):
        hint = f"; for a preset's parameters use Shield.from_preset({params!r})"
    raise InputError(
        f"Shield params must be a safelane.Params or a mapping of its fields; got {_got(params)}{hint}", "params"
    )


def shield_config(config):
    """``None`` (the defaults), a :class:`~safelane.shield.ShieldConfig` or a mapping of its fields."""
    from .core import ShieldConfig

    if config is None:
        return ShieldConfig()
    if isinstance(config, ShieldConfig):
        return config
    if isinstance(config, Mapping):
        return validate_model(ShieldConfig, dict(config), "Shield config")
    raise InputError(
        f"Shield config must be a safelane.shield.ShieldConfig or a mapping of its fields; got {_got(config)}",
        "config",
    )


def shield_variant(variant):
    """A registered variant name, or one name or registry index per row: checked now, returned as given."""
    from .policies import variant_flags

    if isinstance(variant, str):
        n = 1
    else:
        try:
            n = len(np.atleast_1d(np.asarray(variant)))
        except (TypeError, ValueError):
            n = 0
    try:
        variant_flags(variant, max(n, 1))
    except (TypeError, ValueError) as exc:
        raise InputError(f"Shield variant: {exc}", "variant") from exc
    return variant


def preset_parts(preset, config=None):
    """``(params, ShieldConfig)`` of a preset (name, YAML path or :class:`~safelane.sim.preset.Preset`): the
    parameters and the shield settings the built-in simulator gives the shield under that preset (assessment,
    completion rule, monitor, actuation delay, own lane, sensing); ``config`` (a ``ShieldConfig`` or a mapping of
    some of its fields) overrides them."""
    from ..sim.preset import load_preset
    from .core import ShieldConfig

    chosen = load_preset(preset)
    cfg = chosen.sim
    base = cfg.shield
    if config is None:
        return chosen.params, base
    if isinstance(config, ShieldConfig):
        return chosen.params, config
    if isinstance(config, Mapping):
        return chosen.params, validate_model(ShieldConfig, {**base.model_dump(), **dict(config)}, "Shield config")
    return chosen.params, shield_config(config)  # raises, naming the argument


def situation_arg(situation, where: str):
    """``situation`` must be a :class:`~safelane.shield.Situation`."""
    from .situation import Situation

    if not isinstance(situation, Situation):
        raise InputError(
            f"{where}: situation must be a safelane.shield.Situation (build one with Situation.from_arrays); got "
            f"{_got(situation)}",
            "situation",
        )
    return situation


def _is_number(value) -> bool:
    if isinstance(value, np.ndarray):  # (first: the common case, and cheaper than the abstract-class check)
        return value.ndim == 0 and value.dtype.kind in "fiu"
    return isinstance(value, numbers.Real | np.number) and not isinstance(value, bool | np.bool_)


def batch_proposal(proposal, batch: int):
    """``proposal`` with a plain number for ``a_x`` or ``a_y`` broadcast to the batch's shape ``(batch,)`` (one value
    for every row, e.g. ``shield.step(situation, (1.0, 1.5))`` for a batch of one); anything else unchanged — the
    proposal check then names what is wrong with it."""
    if not isinstance(proposal, tuple | list) or len(proposal) != 2:
        return proposal
    return tuple(np.full(batch, float(v)) if _is_number(v) else v for v in proposal)
