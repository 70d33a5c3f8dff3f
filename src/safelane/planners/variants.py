"""Planner variants of the paper (§4.1), registered by name, and the RSS baselines.

A variant is *the information it uses*, not a copy of the supervisor: the supervisor asks the variant where
L1's worst-case deceleration and the follower's assumed type come from. A variant with another ``rule`` than
``"paper"`` is decided by that registered decision rule instead (:mod:`safelane.shield.rules`): the RSS baselines
(:mod:`safelane.baselines.rss`; docs/rss.md).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Variant:
    """Which information a planner variant uses for its worst-case analysis.

    Attributes:
        uses_chain: L1's worst-case deceleration comes from the connected chain (Eqs. 1–3); otherwise L1 may
            brake at ``a_x_d``.
        uses_follower_v2x: a connected follower's declared collaboration is trusted.
        uses_assessment: a non-connected (or untrusted) follower is classified by the aggressiveness
            assessment; otherwise it is always assumed aggressive.
        rule: the decision rule (``"paper"``: the paper's shield; otherwise a name in
            :data:`safelane.shield.rules.DECISION_RULES`).
    """

    name: str
    uses_chain: bool
    uses_follower_v2x: bool
    uses_assessment: bool
    description: str
    rule: str = "paper"


VARIANTS: dict[str, Variant] = {
    v.name: v
    for v in (
        Variant("CV_all", True, True, True, "Whole connected chain for L1's worst case; F's connectivity."),
        Variant("CV_follow", False, True, True, "F's connectivity only; L1 may brake at a_x_d."),
        Variant("CV_none", False, False, True, "No connectivity: L1 at a_x_d, F from the aggressiveness assessment."),
        Variant("No_agg_assess", False, False, False, "L1 at a_x_d, F always assumed aggressive."),
        # RSS baselines (appended: the paper's variants keep their indices). No V2X: every vehicle may brake at
        # brake_max; with V2X: L1's brake_max is its bound from the connected chain (Eqs. 1-3).
        Variant("RSS", False, False, False, "RSS (ad-rss's default parameters), no V2X.", "rss"),
        Variant("RSS_V2X", True, False, False, "RSS (ad-rss's defaults), L1's brake_max from the chain.", "rss"),
        Variant("RSS_matched", False, False, False, "RSS with this world's limits, no V2X.", "rss_matched"),
        Variant("RSS_V2X_matched", True, False, False, "RSS with this world's limits, L1 from the chain.",
                "rss_matched"),
    )
}

#: Registry order (the paper's order, then the baselines); scenario batches store a variant as its index here.
VARIANT_NAMES: tuple[str, ...] = tuple(VARIANTS)
#: The paper's four variants (§4.1), in the paper's order.
PAPER_VARIANT_NAMES: tuple[str, ...] = tuple(name for name, v in VARIANTS.items() if v.rule == "paper")


def get_variant(name: str) -> Variant:
    """The registered variant called ``name``; a clear error lists the valid names otherwise."""
    try:
        return VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown planner variant {name!r}; choose one of {', '.join(VARIANT_NAMES)}") from None
