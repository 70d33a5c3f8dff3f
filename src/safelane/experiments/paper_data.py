"""The paper's published numbers (Table 1) and its checkable claims.

Only the N = 1 and N = 10 rows of Table 1 are in our copy; the N = 3 rows are withheld on purpose (they
validate the calibration) and must never be used to tune anything.
"""

from __future__ import annotations

PLANNERS: tuple[str, ...] = ("CV_all", "CV_follow", "CV_none", "No_agg_assess")
DECELS: tuple[float, ...] = (2.0, 3.0, 4.0, 5.0, 6.0)

#: Table 1 success rates: (N, a_x_N+1_d) -> (CV_all, CV_follow, CV_none, No_agg_assess).
TABLE1: dict[tuple[int, float], tuple[float, float, float, float]] = {
    (1, 2.0): (1.0, 1.0, 0.995, 0.995),
    (1, 3.0): (1.0, 1.0, 0.875, 0.83),
    (1, 4.0): (0.356, 0.337, 0.23, 0.195),
    (1, 5.0): (0.001, 0.0, 0.0, 0.0),
    (1, 6.0): (0.0, 0.0, 0.0, 0.0),
    (10, 2.0): (1.0, 1.0, 1.0, 1.0),
    (10, 3.0): (1.0, 1.0, 1.0, 1.0),
    (10, 4.0): (1.0, 1.0, 0.993, 0.998),
    (10, 5.0): (1.0, 1.0, 0.969, 0.956),
    (10, 6.0): (1.0, 1.0, 0.95, 0.928),
}

#: N values of Table 1 whose rows are published in our copy (N = 3 is predicted, never fitted).
PUBLISHED_N: tuple[int, ...] = (1, 10)


def table1_long() -> list[dict]:
    """Table 1 as tidy rows ``{n_leaders, decel, planner, paper_success}``."""
    return [
        {"n_leaders": n, "decel": d, "planner": p, "paper_success": v}
        for (n, d), values in TABLE1.items()
        for p, v in zip(PLANNERS, values, strict=True)
    ]
