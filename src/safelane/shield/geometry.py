"""The lanes' order in a :class:`~.situation.Situation` — the target lane's ``F ≤ L1 ≤ L2 ≤ … ≤ L(N+1)``, the own
lane's ``L0`` first — and what a break of it gives (:meth:`~.situation.Situation.from_arrays`'s ``geometry``)."""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import InputError


class GeometryWarning(UserWarning):
    """A :class:`Situation` whose lanes are out of order (see :meth:`Situation.from_arrays`)."""


_GEOMETRY = ("warn", "raise", "ignore")


def report_order(situation, geometry: str) -> None:
    """Act on the first break of ``situation``'s lanes' order as ``geometry`` says (``warn``, ``raise``, ``ignore``)."""
    if geometry not in _GEOMETRY:
        raise InputError(f"geometry must be one of {', '.join(_GEOMETRY)}; got {geometry!r}", "geometry")
    problems = [] if geometry == "ignore" else order_problems(situation)
    if not problems:
        return
    field, text = problems[0]
    if geometry == "raise":
        raise InputError(f"Situation.{field}: {text}", field)
    warnings.warn(f"Situation.{field}: {text}. The shield answers it conservatively (no lane change while it lasts); "
                  "see Situation.from_arrays", GeometryWarning, stacklevel=3)  # fmt: skip


def order_problems(situation) -> list[tuple[str, str]]:
    """:meth:`~.situation.Situation.order_problems`."""
    out = []
    x = situation.chain_x
    behind = (x[:, 1:] < x[:, :-1]) & (np.arange(1, x.shape[1])[None, :] <= situation.n_connected[:, None])
    if behind.any():
        r, j = (int(i[0]) for i in np.nonzero(behind))
        out.append(("chain_x", f"L{j + 2} at {x[r, j + 1]:g} m is behind L{j + 1} at {x[r, j]:g} m (row {r}); "
                    "the leaders go nearest first, each at or ahead of the one before it"))  # fmt: skip
    ahead = situation.f_x > x[:, 0]
    if ahead.any():
        r = int(np.argmax(ahead))
        out.append(("f_x", f"F at {situation.f_x[r]:g} m is ahead of L1 at {x[r, 0]:g} m (row {r}); F is the target "
                    "lane's follower, at or behind L1"))  # fmt: skip
    if situation.own_x is not None and situation.own_x.shape[1] > 1:
        ox = situation.own_x
        with np.errstate(invalid="ignore"):
            behind = np.isfinite(ox[:, 1:]) & (ox[:, 1:] < ox[:, :-1])
        if behind.any():
            r, j = (int(i[0]) for i in np.nonzero(behind))
            out.append(("own_x", f"own-lane leader {j + 1} at {ox[r, j + 1]:g} m is behind leader {j} at "
                        f"{ox[r, j]:g} m (row {r}); L0 first, each at or ahead of the one before it"))  # fmt: skip
    return out
