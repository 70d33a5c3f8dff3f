"""One configuration surface: the shield's settings live in ``SimConfig.shield`` (a ``ShieldConfig``) and nowhere
else in ``SimConfig``; the flat keys of earlier presets and code still read, into the one home."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from safelane import load_preset
from safelane.shield import ShieldConfig
from safelane.sim import SimConfig
from safelane.sim.config import SHIELD_KEYS


def test_no_shield_setting_is_copied_into_the_simulators_config():
    shared = set(SimConfig.model_fields) & set(ShieldConfig.model_fields)
    # namesakes of different things: the world's L0 / the shield's keeping p_m to it; the world's delay / the one
    # the shield accounts for (they can differ: a shield that ignores the delay, as the paper's)
    assert shared == {"own_lane", "actuation_delay_s"}
    assert not set(SHIELD_KEYS) & set(SimConfig.model_fields)
    assert set(SHIELD_KEYS.values()) <= set(ShieldConfig.model_fields)


@pytest.mark.parametrize("old, new, value", [(o, n, v) for (o, n), v in zip(SHIELD_KEYS.items(), (
    "slow", 0.7, 0.3, "paper_evasion", 9, 0.33, False, False, False, False), strict=True)])  # fmt: skip
def test_a_flat_key_reads_into_the_shield(old, new, value):
    cfg = SimConfig(**{old: value})
    assert getattr(cfg.shield, new) == value != getattr(ShieldConfig(), new)
    assert cfg.model_copy(update={old: value}) == cfg == SimConfig().model_copy(update={old: value})
    assert SimConfig(shield={new: value}) == cfg


def test_the_shield_accounts_for_the_worlds_delay_unless_told_otherwise():
    assert SimConfig(actuation_delay_s=0.2).shield.actuation_delay_s == 0.2
    assert SimConfig(actuation_delay_s=0.2, shield_delay=False).shield.actuation_delay_s == 0.0
    assert SimConfig(actuation_delay_s=0.2, shield={"actuation_delay_s": 0.1}).shield.actuation_delay_s == 0.1
    follows = SimConfig(actuation_delay_s=0.2).model_copy(update={"actuation_delay_s": 0.3})
    assert follows.shield.actuation_delay_s == 0.3
    ignores = SimConfig(actuation_delay_s=0.2, shield_delay=False).model_copy(update={"actuation_delay_s": 0.3})
    assert ignores.shield.actuation_delay_s == 0.0
    assert load_preset("realistic").sim.shield.actuation_delay_s == load_preset("realistic").sim.actuation_delay_s > 0
    # shield_delay in a copy's update reads as in the constructor (it used to clash with the copied shield's delay)
    realistic = load_preset("realistic").sim
    assert realistic.model_copy(update={"shield_delay": False}).shield.actuation_delay_s == 0.0
    assert realistic.model_copy(update={"shield_delay": False}).actuation_delay_s == 0.2
    both = SimConfig(shield_delay=False).model_copy(update={"actuation_delay_s": 0.3, "shield_delay": True})
    assert both.shield.actuation_delay_s == 0.3
    with pytest.raises(ValueError, match=r"shield_delay and shield\.actuation_delay_s"):
        realistic.model_copy(update={"shield_delay": True, "shield": {"actuation_delay_s": 0.1}})


def test_contradictions_and_bad_values_are_refused_naming_the_field():
    with pytest.raises(ValidationError, match=r"assessment and shield\.assessment both given"):
        SimConfig(assessment="slow", shield={"assessment": "truth"})
    with pytest.raises(ValidationError, match=r"shield_delay and shield\.actuation_delay_s"):
        SimConfig(shield_delay=False, shield={"actuation_delay_s": 0.1})
    with pytest.raises(ValidationError, match="assess_window"):
        SimConfig(assess_window=1)
    with pytest.raises(ValidationError, match="assess_window"):  # pydantic's own model_copy would not validate
        SimConfig().model_copy(update={"assess_window": 1})
    with pytest.raises(ValidationError, match="no_such_knob"):
        SimConfig().model_copy(update={"no_such_knob": 1})


def test_every_shipped_preset_reads_into_the_same_shield_as_its_flat_keys_say():
    import yaml

    from safelane.experiments.calibration import PRESET_DIR

    for path in sorted(PRESET_DIR.glob("*.yaml")):
        flat = yaml.safe_load(path.read_text())["sim"]
        shield = load_preset(path.stem).sim.shield
        for old, new in SHIELD_KEYS.items():
            if old in flat:
                assert getattr(shield, new) == flat[old], (path.name, old)
