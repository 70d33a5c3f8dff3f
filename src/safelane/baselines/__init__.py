"""Baselines from outside the paper, on the same scenarios: Responsibility-Sensitive Safety (RSS).

* :mod:`.rss` — RSS's parameters (ad-rss's vocabulary), its closed forms vectorized in NumPy, and the RSS lane-change
  rule the shield applies for the variants ``RSS``, ``RSS_V2X`` (and their ``_matched`` forms);
* :mod:`.rss_adrss` — the same closed forms through ad-rss itself (extra ``rss``), the reference the NumPy version
  is tested against.
"""

from .rss import RSS_PARAMETER_SETS, RssParams, lateral_safe_distance, longitudinal_safe_distance, rss_params_for

__all__ = [
    "RSS_PARAMETER_SETS",
    "RssParams",
    "lateral_safe_distance",
    "longitudinal_safe_distance",
    "rss_params_for",
]
