"""Issue 31: the Shield's arguments are checked when it is built (field, value, what is allowed), a preset builds a
Shield, and a batch of one takes plain numbers as its proposal."""

from __future__ import annotations

import numpy as np
import pytest

from safelane import Params
from safelane.errors import InputError
from safelane.shield import Shield, ShieldConfig, Situation


def _situation(b: int = 1) -> Situation:
    return Situation.from_arrays(t=0.0, ego=(np.zeros(b), 0.0, 30.0, 0.0), follower=(-20.0, 30.0),
                                 leaders=([20.0], [30.0]), n_connected=0)  # fmt: skip


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ("paper", r"Shield params must be a safelane.Params .* got 'paper' \(str\); .*Shield.from_preset\('paper'\)"),
        (42, r"Shield params must be a safelane.Params or a mapping of its fields; got 42 \(int\)"),
        ({"p_m": -1}, r"Shield params: field 'p_m' = -1: Input should be greater than 0"),
        ({"p_mm": 8.0}, r"unknown field 'p_mm'"),
    ],
)
def test_shield_refuses_bad_params_at_construction(params, match):
    with pytest.raises(InputError, match=match):
        Shield(params)


def test_shield_refuses_bad_config_and_variant_at_construction():
    with pytest.raises(InputError, match=r"Shield config must be a safelane.shield.ShieldConfig .* got 'fast'"):
        Shield(config="fast")
    with pytest.raises(InputError, match=r"Shield config: field 'assess_window' = 1"):
        Shield(config={"assess_window": 1})
    with pytest.raises(InputError, match=r"Shield variant: unknown planner variant 'CV_any'"):
        Shield(variant="CV_any")


def test_shield_takes_mappings_like_simulate():
    shield = Shield({"p_m": 8.0}, config={"monitor": False})
    assert shield.params == Params(p_m=8.0) and shield.config == ShieldConfig(monitor=False)


def test_shield_from_preset_takes_the_presets_params_and_shield_settings():
    from safelane import load_preset

    preset = load_preset("paper")
    shield = Shield.from_preset("paper", variant="CV_follow")
    assert shield.params == preset.params and shield.variant == "CV_follow"
    cfg = shield.config
    assert cfg == preset.sim.shield and not cfg.monitor  # the preset's shield settings, its one home
    assert Shield.from_preset("paper", config={"monitor": True}).config.monitor
    default = Shield.from_preset()  # the paper preset by default, as safelane.load_preset's examples
    assert (default.params, default.config, default.variant) == (preset.params, preset.sim.shield, "CV_all")
    with pytest.raises(InputError, match="preset 'nope' not found"):
        Shield.from_preset("nope")


def test_shield_step_broadcasts_plain_numbers_for_a_batch_of_one():
    sit = _situation()
    shield = Shield()
    shield.reset(sit)
    decision = shield.step(sit, (1.0, 1.5))
    ref = Shield()
    ref.reset(sit)
    expected = ref.step(sit, (np.array([1.0]), np.array([1.5])))
    assert decision.a_x.shape == (1,)
    np.testing.assert_array_equal(decision.a_x, expected.a_x)
    np.testing.assert_array_equal(decision.behaviour, expected.behaviour)


def test_shield_step_broadcasts_numbers_over_a_batch_and_names_a_wrong_shape_once():
    sit = _situation(3)
    shield = Shield()
    shield.reset(sit)
    assert shield.step(sit, (0.0, np.float64(0.5))).a_y.shape == (3,)
    with pytest.raises(ValueError, match=r"^the nominal planner returned a_x of shape \(2,\); expected \(3,\)$"):
        shield.step(sit, (np.zeros(2), 0.0))


def test_shield_reset_and_step_name_a_situation_that_is_not_one():
    shield = Shield()
    with pytest.raises(InputError, match=r"Shield.reset: situation must be a safelane.shield.Situation"):
        shield.reset({"ego_x": 0.0})
    shield.reset(_situation())
    with pytest.raises(InputError, match=r"Shield.step: situation must be a safelane.shield.Situation"):
        shield.step({"ego_x": 0.0}, (0.0, 0.0))
