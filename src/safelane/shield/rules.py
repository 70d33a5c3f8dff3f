"""Decision rules other than the paper's, registered by name and chosen by variant (``Variant.rule``).

The shield's core (:func:`safelane.shield.core.step`) decides every row with the paper's rule (proceed / hesitate /
abort on a verified evasion plan, :mod:`.decide`) except the rows whose variant names another rule; those it hands,
once per period, to that rule's ``decide``. A batch of the paper's variants alone never reaches this module's rules:
their code path is the paper's, unchanged.

* ``rss`` — Responsibility-Sensitive Safety with ad-rss's documented default parameters
  (:class:`safelane.baselines.rss_rule.RssRule`; variants ``RSS``, ``RSS_V2X``);
* ``rss_matched`` — the same rule with this world's limits (``RssParams.matched``; ``RSS_matched``,
  ``RSS_V2X_matched``).

A rule is an object with ``decide(inputs: RuleInputs, params) -> (proceed, hesitate, respond, a_x, a_y, completing)``
(each ``(k,)`` over the rule's rows; a row in none of the three masks was complete and follows); register it here
(wrapped in :class:`Coded`, which turns the masks into the shield's behaviour codes; a responding row is an abort) and
name it in a :class:`~safelane.planners.variants.Variant`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..baselines.rss import RSS_FIELDS, rss_vector
from ..baselines.rss_rule import RssRule
from ..planners.variants import VARIANT_NAMES, VARIANTS
from .decide import ABORT, COMPLETED, HESITATE, PROCEED


class Coded:
    """A rule's masks as the shield's behaviour codes: ``decide(inputs, params) -> (behaviour, a_x, a_y,
    completing)``."""

    def __init__(self, rule):
        self.rule = rule

    def __repr__(self) -> str:
        return repr(self.rule)

    def decide(self, inputs, params):
        proceed, hesitate, respond, a_x, a_y, completing = self.rule.decide(inputs, params)
        behaviour = np.select([proceed, hesitate, respond], [PROCEED, HESITATE, ABORT], COMPLETED)
        return behaviour, a_x, a_y, completing


DECISION_RULES = {"rss": Coded(RssRule("ad_rss")), "rss_matched": Coded(RssRule("matched"))}

_RULE_NAMES = tuple(dict.fromkeys(v.rule for v in VARIANTS.values()))  # each registered rule once, "paper" among them
_RULE_CODE = np.array([_RULE_NAMES.index(v.rule) for v in VARIANTS.values()])  # per variant index


@dataclass(frozen=True)
class RuleInputs:
    """What a rule sees for its rows (``(k,)`` arrays unless noted, shield frame): the ego, the chain ``L1, L2, …``
    (``(k, M)``), F and the own lane's leader ``L0`` (``own_x = +inf`` where there is none; ``None``: the paper's empty
    own lane), the checked and clipped proposal (``invalid`` rows hold zeros), the lateral hesitation, L1's
    worst-case deceleration from the information the variant uses (``uses_chain``: from the connected chain;
    otherwise ``a_x_d``), every chain vehicle's bound from the chain analysis (``(k, M)``; meaningful where
    ``uses_chain`` and for the ``n_connected`` connected leaders), whether the lane change was complete before this
    period, and the lane keeping's lateral command after completion."""

    ego_x: np.ndarray
    ego_y: np.ndarray
    ego_vx: np.ndarray
    ego_vy: np.ndarray
    chain_x: np.ndarray
    chain_v: np.ndarray
    f_x: np.ndarray
    f_v: np.ndarray
    a_x: np.ndarray
    a_y: np.ndarray
    a_y_hesitate: np.ndarray
    invalid: np.ndarray
    l1_decel: np.ndarray
    uses_chain: np.ndarray
    completed: np.ndarray
    chain_bounds: np.ndarray
    n_connected: np.ndarray
    a_y_keep: np.ndarray  # the lateral command after completion (stages.lane_keep_accel: centred in the target lane)
    own_x: np.ndarray | None = None  # L0, the ego's own-lane leader (+inf: none), at the frame's state; None: no L0
    own_v: np.ndarray | None = None


def rule_rows(variant, n: int) -> list[tuple[object, np.ndarray]]:
    """``[(rule, rows)]`` for the rows whose variant names a registered rule other than the paper's (empty for the
    paper's variants). ``variant``: a name, or ``(n,)`` names or registry indices (validated by
    :func:`.policies.variant_flags`)."""
    if isinstance(variant, str):
        rule = VARIANTS[variant].rule
        return [] if rule == "paper" else [(DECISION_RULES[rule], np.arange(n))]
    arr = np.asarray(variant)
    idx = np.array([VARIANT_NAMES.index(v) for v in arr.tolist()]) if arr.dtype.kind in "US" else arr
    codes = _RULE_CODE[idx]
    present = np.flatnonzero(np.bincount(codes, minlength=len(_RULE_NAMES)))  # integer counting, not a string sort
    named = [(_RULE_NAMES[c], c) for c in present.tolist() if _RULE_NAMES[c] != "paper"]
    return [(DECISION_RULES[name], np.flatnonzero(codes == c)) for name, c in sorted(named)]


def uncompiled_rules(ruled) -> list[str]:
    """The rules among ``ruled`` (:func:`rule_rows`' list) that the compiled period does not implement (it implements
    :class:`~safelane.baselines.rss_rule.RssRule` with any parameter set, ``shield/_fast_rules.py``)."""
    return [repr(getattr(coded, "rule", coded)) for coded, _ in ruled
            if not isinstance(getattr(coded, "rule", None), RssRule)]


def rule_table(ruled, n: int, params) -> np.ndarray:
    """The compiled period's per-row rule vectors (``shield/_fast_rules.RULE``): ``(n, 1 + len(RSS_FIELDS))``, the
    first column 1 where RSS decides the row, then its parameters; ``(n, 1)`` zeros where no row is ruled. ``ruled``:
    :func:`rule_rows`' list, every rule an :class:`~safelane.baselines.rss_rule.RssRule`."""
    if not ruled:
        return np.zeros((n, 1))
    out = np.zeros((n, 1 + len(RSS_FIELDS)))
    for coded, rows in ruled:
        out[rows, 0] = 1.0
        out[rows, 1:] = rss_vector(coded.rule.params(params))
    return out
