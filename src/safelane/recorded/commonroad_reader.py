"""CommonRoad scenario XML → :class:`~.recording.Recording` (extra ``commonroad``: commonroad-io, imported lazily).

Only ``commonroad.common.reader.file_reader_xml.XMLFileReader`` is imported: ``commonroad.common.file_reader``
pulls protobuf-generated code that breaks under the protobuf the ONNX export needs.

**The lane-based frame.** The lanelets are grouped into lanes (chains joined by predecessor/successor links). The
reference line is the centreline of the longest lane, in its driving direction; every point is projected onto it:
``x`` is the arc length of the nearest point of the polyline (extended straight beyond both ends), ``y`` the signed
distance to it, positive to the left of the direction of travel. On a roughly straight road (CommonRoad's US-101
snippets) lanes are then strips of nearly constant ``y``: each lane's bounds are the medians of its lanelets'
projected bound vertices (neighbours share the mean of their facing bounds), and a vehicle's lane is the one
whose strip holds its centre (and whose lanelets cover its ``x``). Lanes are numbered 1, 2, … from the left, as
NGSIM numbers them.

Obstacles: every dynamic obstacle (the planning problem's vehicle is not one: CommonRoad removes it). Its state's
``position`` is the shape's centre; ``velocity`` is the speed along its heading; ``acceleration`` where the file
has it, else the central difference of the speed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .recording import NO_LANE, Lanes, Recording, _derivative, check_recording

INSTALL_HINT = 'commonroad-io is not installed: pip install "safelane[commonroad]"'


def _reader():
    try:
        from commonroad.common.reader.file_reader_xml import XMLFileReader
    except ImportError as exc:
        raise ImportError(INSTALL_HINT) from exc
    return XMLFileReader


def available() -> bool:
    """commonroad-io imports."""
    try:
        _reader()
    except ImportError:
        return False
    return True


def load_commonroad(path) -> Recording:
    """The recording of a CommonRoad scenario file (module docstring: frame, lanes, obstacles).

    Raises :class:`~safelane.errors.InputError` naming the file when it is missing, is not CommonRoad XML, or holds
    no lanelet or no dynamic obstacle; ``ImportError`` with the install hint without commonroad-io."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{str(path)!r}: no such file", str(path))
    reader = _reader()
    try:
        scenario, _ = reader(str(path)).open()
    except Exception as exc:  # lxml, a missing element, a bad value: all mean "not a scenario we can read"
        raise InputError(f"{str(path)!r}: not a readable CommonRoad scenario ({type(exc).__name__}: {exc})",
                         str(path)) from exc  # fmt: skip
    lanelets = list(scenario.lanelet_network.lanelets)
    if not lanelets:
        raise InputError(f"{str(path)!r}: the scenario has no lanelet (no road to project onto)", str(path))
    obstacles = list(scenario.dynamic_obstacles)
    if not obstacles:
        raise InputError(f"{str(path)!r}: the scenario has no dynamic obstacle (no recorded vehicle)", str(path))
    return recording_from_scenario(lanelets, obstacles, float(scenario.dt), str(path))


def _lane_chains(lanelets) -> dict[int, int]:
    """lanelet id → chain number (lanelets joined by predecessor/successor links)."""
    ids = [ll.lanelet_id for ll in lanelets]
    parent = {i: i for i in ids}

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for ll in lanelets:
        for other in (*ll.successor, *ll.predecessor):
            if other in parent:
                parent[root(other)] = root(ll.lanelet_id)
    roots = sorted({root(i) for i in ids})
    return {i: roots.index(root(i)) for i in ids}


def _chain_centreline(lanelets, members: list[int]) -> np.ndarray:
    """The centreline of one chain from its first lanelet along successor links, ``(P, 2)``."""
    by_id = {ll.lanelet_id: ll for ll in lanelets}
    inside = set(members)
    first = next(i for i in members if not set(by_id[i].predecessor) & inside)
    points, current, seen = [], first, set()
    while current is not None and current not in seen:
        seen.add(current)
        vertices = np.asarray(by_id[current].center_vertices, float)
        points.append(vertices if not points else vertices[1:])
        current = next((s for s in by_id[current].successor if s in inside), None)
    return np.concatenate(points)


def project(points: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(s, d)`` of ``points (..., 2)`` on the polyline ``line (P, 2)``: arc length of the nearest point (the first
    and last segments extended straight beyond the ends) and signed distance, positive to the left."""
    points = np.asarray(points, float)
    flat = points.reshape(-1, 2)
    seg = np.diff(line, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    keep = seg_len > 1e-9
    start, seg, seg_len = line[:-1][keep], seg[keep], seg_len[keep]
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])[:-1]
    rel = flat[:, None, :] - start[None, :, :]
    u = np.einsum("nkj,kj->nk", rel, seg) / seg_len**2
    lo = np.where(np.arange(len(seg)) == 0, -np.inf, 0.0)
    hi = np.where(np.arange(len(seg)) == len(seg) - 1, np.inf, 1.0)
    u = np.clip(u, lo, hi)
    nearest = start[None] + u[..., None] * seg[None]
    dist = np.linalg.norm(flat[:, None, :] - nearest, axis=2)
    k = np.argmin(dist, axis=1)
    rows = np.arange(len(flat))
    s = cum[k] + u[rows, k] * seg_len[k]
    cross = seg[k, 0] * rel[rows, k, 1] - seg[k, 1] * rel[rows, k, 0]
    d = cross / seg_len[k]
    return s.reshape(points.shape[:-1]), d.reshape(points.shape[:-1])


def _lanes(lanelets, line: np.ndarray, chain_of: dict[int, int]) -> tuple[Lanes, dict[int, int]]:
    """The lanes (numbered 1.. from the left) and chain number → lane id."""
    n = max(chain_of.values()) + 1
    left_d, right_d = [[] for _ in range(n)], [[] for _ in range(n)]
    s_min, s_max = np.full(n, np.inf), np.full(n, -np.inf)
    for ll in lanelets:
        c = chain_of[ll.lanelet_id]
        s_l, d_l = project(np.asarray(ll.left_vertices, float), line)
        s_r, d_r = project(np.asarray(ll.right_vertices, float), line)
        left_d[c].append(d_l)
        right_d[c].append(d_r)
        s_min[c] = min(s_min[c], s_l.min(), s_r.min())
        s_max[c] = max(s_max[c], s_l.max(), s_r.max())
    y_left = np.array([np.median(np.concatenate(v)) for v in left_d])
    y_right = np.array([np.median(np.concatenate(v)) for v in right_d])
    order = np.argsort(-(y_left + y_right))  # leftmost first
    y_left, y_right = y_left[order], y_right[order]
    # Neighbouring strips share one line (the mean of their facing bounds): no gap, no overlap between lanes.
    shared = 0.5 * (y_right[:-1] + y_left[1:])
    y_right[:-1], y_left[1:] = shared, shared
    lane_of_chain = {int(c): k + 1 for k, c in enumerate(order)}
    left = np.full(n, NO_LANE)
    right = np.full(n, NO_LANE)
    for ll in lanelets:
        c = chain_of[ll.lanelet_id]
        if ll.adj_left is not None and ll.adj_left_same_direction and ll.adj_left in chain_of:
            left[c] = lane_of_chain[chain_of[ll.adj_left]]
        if ll.adj_right is not None and ll.adj_right_same_direction and ll.adj_right in chain_of:
            right[c] = lane_of_chain[chain_of[ll.adj_right]]
    lanes = Lanes(
        ids=np.arange(1, n + 1), y_right=y_right, y_left=y_left, left=left[order], right=right[order],
        x_start=s_min[order], x_end=s_max[order],
    )  # fmt: skip
    return lanes, lane_of_chain


def lane_of(lanes: Lanes, x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The id of the lane whose strip holds each point (:data:`NO_LANE` where none); any shape."""
    out = np.full(np.shape(x), NO_LANE)
    for k in range(len(lanes.ids)):  # a handful of lanes; every point at once
        strip = (y >= lanes.y_right[k]) & (y < lanes.y_left[k])
        inside = valid & strip & (x >= lanes.x_start[k]) & (x <= lanes.x_end[k])
        out = np.where(inside & (out == NO_LANE), lanes.ids[k], out)
    return out


def recording_from_scenario(lanelets, obstacles, dt: float, source: str) -> Recording:
    """The recording of commonroad-io's lanelets and dynamic obstacles (see the module docstring)."""
    chain_of = _lane_chains(lanelets)
    chains = {}
    for lid, c in chain_of.items():
        chains.setdefault(c, []).append(lid)
    lines = {c: _chain_centreline(lanelets, members) for c, members in chains.items()}
    length_of = {c: np.linalg.norm(np.diff(v, axis=0), axis=1).sum() for c, v in lines.items()}
    line = lines[max(length_of, key=length_of.get)]
    lanes, _ = _lanes(lanelets, line, chain_of)

    states = [[o.initial_state, *(o.prediction.trajectory.state_list if o.prediction is not None else [])]
              for o in obstacles]  # fmt: skip
    first = min(s[0].time_step for s in states)
    last = max(s.time_step for ss in states for s in ss)
    v, t = len(obstacles), last - first + 1
    pos = np.full((v, t, 2), np.nan)
    speed = np.full((v, t), np.nan)
    accel = np.full((v, t), np.nan)
    has_accel = np.zeros((v, t), bool)
    for i, ss in enumerate(states):  # unpacking the source's objects; the arrays below are built once
        for s in ss:
            k = s.time_step - first
            pos[i, k] = s.position
            speed[i, k] = s.velocity
            a = getattr(s, "acceleration", None)
            if a is not None:
                accel[i, k], has_accel[i, k] = a, True
    valid = np.isfinite(pos).all(-1) & np.isfinite(speed)
    x, y = project(np.where(valid[..., None], pos, 0.0), line)
    x, y = np.where(valid, x, np.nan), np.where(valid, y, np.nan)
    speed = np.where(valid, speed, np.nan)
    accel = np.where(has_accel, accel, _derivative(speed, valid, dt))
    accel = np.where(valid, accel, np.nan)
    length = np.array([getattr(o.obstacle_shape, "length", np.nan) for o in obstacles], float)
    width = np.array([getattr(o.obstacle_shape, "width", np.nan) for o in obstacles], float)
    rec = Recording(
        source=source, dt=dt, t0=first * dt, vehicle_ids=np.array([o.obstacle_id for o in obstacles], np.int64),
        x=x, y=y, speed=speed, accel=accel, lane=lane_of(lanes, x, y, valid), length=length, width=width,
        valid=valid, lanes=lanes,
        frame="CommonRoad: x = arc length along the centreline of the longest lane, y = signed distance to it "
        "(left positive); lanes numbered from the left",
    )  # fmt: skip
    return check_recording(rec)
