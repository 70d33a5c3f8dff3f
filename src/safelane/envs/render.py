"""A top-down picture of one lane change, drawn with NumPy alone (``render_mode="rgb_array"``).

The road runs left to right (the direction of travel); the target lane is the upper one. The view follows the ego:
``BEHIND_M`` behind it to ``AHEAD_M`` ahead. Longitudinal and lateral scales differ (``PX_PER_M_X`` and
``PX_PER_M_Y``): two lanes are 7 m wide and the view is 120 m long, so a picture at one scale would be a thin strip.

Colours: the ego green (red once it has collided), F magenta, the connected leaders ``L1 … LN`` blue, ``L(N+1)``
(not connected, the one that brakes) orange, the own lane's leader ``L0`` grey; lane edges white, the boundary
between the lanes dashed.
"""

from __future__ import annotations

import numpy as np

from ..params import Params

BEHIND_M, AHEAD_M = 40.0, 80.0
PX_PER_M_X, PX_PER_M_Y = 5.0, 10.0
MARGIN_PX = 20
WIDTH = int((BEHIND_M + AHEAD_M) * PX_PER_M_X)

GRASS = (70, 110, 60)
ROAD = (90, 90, 90)
MARKING = (235, 235, 235)
EGO, EGO_CRASHED = (40, 200, 60), (230, 30, 30)
FOLLOWER, CONNECTED, LAST, OWN = (200, 60, 200), (60, 110, 230), (245, 150, 40), (170, 170, 170)


def height(params: Params) -> int:
    return int(2 * params.lane_width * PX_PER_M_Y) + 2 * MARGIN_PX


def _box(img: np.ndarray, x_px: float, y_px: float, length_px: float, width_px: float, colour) -> None:
    """Fill the axis-aligned rectangle centred at ``(x_px, y_px)``, clipped to the picture."""
    h, w = img.shape[:2]
    x0, x1 = round(x_px - length_px / 2), round(x_px + length_px / 2)
    y0, y1 = round(y_px - width_px / 2), round(y_px + width_px / 2)
    x0, x1, y0, y1 = max(x0, 0), min(x1, w), max(y0, 0), min(y1, h)
    if x0 < x1 and y0 < y1:
        img[y0:y1, x0:x1] = colour


def draw_scene(params: Params, ego, others, collided: bool = False) -> np.ndarray:
    """``(H, W, 3)`` uint8: the road and the vehicles.

    Args:
        ego: ``(x, y)`` in the shield's frame (``y = 0`` the original lane's centre, ``lane_width`` the target's).
        others: ``(x, y, colour)`` of the other vehicles (the same frame); those outside the view are left out.
    """
    prm = params
    h = height(prm)
    img = np.empty((h, WIDTH, 3), np.uint8)
    img[:] = GRASS
    top = 1.5 * prm.lane_width  # the target lane's outer edge, at the picture's MARGIN_PX

    def row(y: float) -> float:
        return MARGIN_PX + (top - y) * PX_PER_M_Y

    img[int(row(top)) : int(row(-0.5 * prm.lane_width)), :] = ROAD
    for edge in (top, -0.5 * prm.lane_width):
        r = int(min(max(row(edge), 0), h - 2))
        img[r : r + 2, :] = MARKING
    ex, ey = ego
    r = int(row(0.5 * prm.lane_width))
    dash = ((np.arange(WIDTH) / PX_PER_M_X + ex - BEHIND_M) % 12.0) < 6.0  # 6 m dashes, 6 m gaps, fixed to the road
    img[r : r + 2, dash] = MARKING

    def column(x: float) -> float:
        return (x - ex + BEHIND_M) * PX_PER_M_X

    length, width = prm.vehicle_length * PX_PER_M_X, prm.vehicle_width * PX_PER_M_Y
    for x, y, colour in others:
        if np.isfinite(x) and -BEHIND_M - prm.vehicle_length <= x - ex <= AHEAD_M + prm.vehicle_length:
            _box(img, column(x), row(y), length, width, colour)
    _box(img, column(ex), row(ey), length, width, EGO_CRASHED if collided else EGO)
    return img


def task_frame(task, row: int = 0) -> np.ndarray:
    """The picture of row ``row`` of a :class:`~safelane.envs.LaneChangeTask` (the empty road before a reset)."""
    prm = task.params
    state, batch = task.state, task.batch
    if state is None or batch is None:
        return draw_scene(prm, (0.0, 0.0), [])
    ex, ey = float(state.ego[0][row]), float(state.ego[1][row])
    n = int(batch.n_connected[row])
    others = []
    for slot in range(state.x.shape[1]):
        if not batch.valid[row, slot]:
            continue
        colour = FOLLOWER if slot == 0 else (CONNECTED if slot <= n else LAST)
        others.append((float(state.x[row, slot]), prm.lane_width, colour))
    if state.l0 is not None:  # the own lane: L0 and any vehicles ahead of it
        others.extend((float(x), 0.0, OWN) for x in state.l0[0][row] if np.isfinite(x))
    return draw_scene(prm, (ex, ey), others, collided=bool(state.collided[row]))
