"""NGSIM trajectory files (US-101, I-80, …; the official column layout) → :class:`~.recording.Recording`.

Columns read (the official names; others, e.g. the 2017 re-release's ``Location``/``O_Zone``, are ignored):
``Vehicle_ID, Frame_ID, Total_Frames, Global_Time, Local_X, Local_Y, Global_X, Global_Y, v_Length, v_Width,
v_Class, v_Vel, v_Acc, Lane_ID, Preceding, Following, Space_Headway, Time_Headway``; comma-, tab- or
space-separated, with or without the header line (without it, the columns are taken in that order).

Units and frame: feet → metres (× 0.3048); frames are 0.1 s (``Frame_ID``; ``Global_Time`` in ms is checked
against it); ``x`` is ``Local_Y`` (the front centre, along the direction of travel) less half the vehicle's
length, i.e. its centre; ``y = −Local_X`` (``Local_X`` grows to the right from the road's left edge; the
recording's ``y`` is left-positive). Lane ids are NGSIM's ``Lane_ID`` (1 = leftmost); lanes ``1..6`` are
neighbours in order (US-101's 6 is the auxiliary lane), higher ids (on- and off-ramps) have no neighbour. NGSIM
gives no lane geometry: each line is estimated as the midpoint of the median lateral positions of the two lanes'
vehicles, the outer edges half a median lane width out.

Smoothing: NGSIM's positions carry measurement noise that differentiation amplifies (its own ``v_Vel``/``v_Acc``
are known to be unusable: Punzo, Borzacchiello & Ciuffo 2011). As Thiemann, Treiber & Kesting (2008) and
Montanino & Punzo (2015) do, the positions are smoothed with a symmetric exponential moving average (sEMA, width
``T_pos`` = 0.5 s; the kernel ``exp(−|k|·dt/T)`` over ``|k| ≤ 3·T/dt``, the window shrunk symmetrically near a
trajectory's ends) and then differentiated: the speed is the central difference of the smoothed ``x``, smoothed
again (``T_speed`` = 1 s), the acceleration the central difference of that speed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .recording import NO_LANE, Lanes, Recording, _derivative, check_recording

FEET_M = 0.3048
DT_S = 0.1
COLUMNS = (
    "Vehicle_ID", "Frame_ID", "Total_Frames", "Global_Time", "Local_X", "Local_Y", "Global_X", "Global_Y",
    "v_Length", "v_Width", "v_Class", "v_Vel", "v_Acc", "Lane_ID", "Preceding", "Following", "Space_Headway",
    "Time_Headway",
)  # fmt: skip
#: The columns the loader uses (the others may hold anything).
NEEDED = ("Vehicle_ID", "Frame_ID", "Global_Time", "Local_X", "Local_Y", "v_Length", "v_Width", "Lane_ID")
#: Lanes that are neighbours in id order (US-101 and I-80: 1..6 main and auxiliary; 7, 8 are ramps).
MAIN_LANES = range(1, 7)
T_POS_S = 0.5
T_SPEED_S = 1.0


def _read_table(path: Path):
    import pandas as pd

    with path.open("r", encoding="utf-8", errors="replace") as fh:
        first = fh.readline()
    if not first.strip():
        raise InputError(f"{str(path)!r}: empty file; expected an NGSIM trajectory table", str(path))
    sep = "," if "," in first else r"\s+"
    has_header = any(c.isalpha() for c in first.replace("e+", "").replace("E+", "").replace("e-", ""))
    try:
        if has_header:
            table = pd.read_csv(path, sep=sep, engine="c" if sep == "," else "python")
            table.columns = [str(c).strip() for c in table.columns]
        else:
            table = pd.read_csv(path, sep=sep, header=None, engine="c" if sep == "," else "python")
            if table.shape[1] < len(COLUMNS):
                raise InputError(f"{str(path)!r}: {table.shape[1]} columns and no header; an NGSIM trajectory file "
                                 f"has {len(COLUMNS)} ({', '.join(COLUMNS)})", str(path))  # fmt: skip
            table = table.iloc[:, : len(COLUMNS)]
            table.columns = list(COLUMNS)
    except (ValueError, pd.errors.ParserError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{str(path)!r}: not a readable table ({exc})", str(path)) from exc
    missing = [c for c in NEEDED if c not in table.columns]
    if missing:
        raise InputError(f"{str(path)!r}: missing column {missing[0]!r} (an NGSIM trajectory file has "
                         f"{', '.join(COLUMNS)})", str(path))  # fmt: skip
    for column in NEEDED:
        values = pd.to_numeric(table[column], errors="coerce")
        bad = ~np.isfinite(values.to_numpy(float))
        if bad.any():
            row = int(np.argmax(bad))
            value = table[column].iloc[row]
            raise InputError(f"{str(path)!r}: column {column!r}, data row {row + 1}: {value!r} is not a number",
                             str(path))  # fmt: skip
        table[column] = values
    if table.empty:
        raise InputError(f"{str(path)!r}: no data rows", str(path))
    return table


def sema(values: np.ndarray, valid: np.ndarray, width_s: float, dt: float) -> np.ndarray:
    """Symmetric exponential moving average along the last axis of ``(V, T)`` values (module docstring): kernel
    ``exp(−|k|·dt/width_s)`` for ``|k| ≤ 3·width_s/dt``, shrunk symmetrically to stay inside each run of valid
    frames. ``NaN`` where invalid."""
    delta = width_s / dt
    reach = int(np.ceil(3.0 * delta))
    v, t = values.shape
    # distance to the end of the valid run on each side bounds the symmetric window
    left = np.zeros((v, t), np.int64)
    right = np.zeros((v, t), np.int64)
    for k in range(1, t):  # over frames only
        left[:, k] = np.where(valid[:, k] & valid[:, k - 1], left[:, k - 1] + 1, 0)
    for k in range(t - 2, -1, -1):
        right[:, k] = np.where(valid[:, k] & valid[:, k + 1], right[:, k + 1] + 1, 0)
    half = np.minimum(np.minimum(left, right), reach)
    clean = np.where(valid, values, 0.0)
    num = clean.copy()
    den = np.ones((v, t))
    for k in range(1, reach + 1):
        w = np.exp(-k / delta)
        use = half >= k
        before = np.zeros((v, t))
        after = np.zeros((v, t))
        before[:, k:] = clean[:, :-k]
        after[:, :-k] = clean[:, k:]
        num += np.where(use, w * (before + after), 0.0)
        den += np.where(use, 2.0 * w, 0.0)
    return np.where(valid, num / den, np.nan)


def _lanes(lane: np.ndarray, y: np.ndarray, valid: np.ndarray) -> Lanes:
    ids = np.unique(lane[valid & (lane != NO_LANE)]).astype(np.int64)
    centres = np.array([np.median(y[valid & (lane == i)]) for i in ids])
    main = np.isin(ids, MAIN_LANES)
    y_left = np.full(len(ids), np.nan)
    y_right = np.full(len(ids), np.nan)
    left = np.full(len(ids), NO_LANE)
    right = np.full(len(ids), NO_LANE)
    order = np.flatnonzero(main)[np.argsort(ids[main])]  # main lanes, left to right
    if len(order):
        c = centres[order]
        lines = 0.5 * (c[:-1] + c[1:])
        half = 0.5 * (np.median(np.abs(np.diff(c))) if len(c) > 1 else 12.0 * FEET_M)
        y_left[order] = np.concatenate([[c[0] + half], lines])
        y_right[order] = np.concatenate([lines, [c[-1] - half]])
        consecutive = np.diff(ids[order]) == 1
        left[order[1:]] = np.where(consecutive, ids[order[:-1]], NO_LANE)
        right[order[:-1]] = np.where(consecutive, ids[order[1:]], NO_LANE)
    ramps = ~main
    y_left[ramps] = centres[ramps] + 6.0 * FEET_M
    y_right[ramps] = centres[ramps] - 6.0 * FEET_M
    inf = np.full(len(ids), np.inf)
    return Lanes(ids=ids, y_right=y_right, y_left=y_left, left=left, right=right, x_start=-inf, x_end=inf)


def load_ngsim(path, frames: tuple[int, int] | None = None) -> Recording:
    """The recording of an NGSIM trajectory file (module docstring: columns, units, frame, smoothing).

    ``frames``: keep only ``Frame_ID`` in ``[first, last]`` (a whole 15-minute file is ~9,000 frames × ~2,000
    vehicles: cut it into windows to bound the memory). A missing file, a missing or non-numeric column, frames
    that are not 0.1 s apart: :class:`~safelane.errors.InputError` naming the file and the column."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{str(path)!r}: no such file", str(path))
    table = _read_table(path)
    if frames is not None:
        table = table[(table["Frame_ID"] >= frames[0]) & (table["Frame_ID"] <= frames[1])]
        if table.empty:
            raise InputError(f"{str(path)!r}: no row with Frame_ID in [{frames[0]}, {frames[1]}]", str(path))
    frame = table["Frame_ID"].to_numpy(np.int64)
    time_ms = table["Global_Time"].to_numpy(float)
    offset = time_ms - frame * DT_S * 1000.0
    if len(offset) > 1 and np.ptp(offset) > 1.0:  # a shared clock: Global_Time = Frame_ID · 100 ms + constant
        raise InputError(f"{str(path)!r}: column 'Global_Time' is not Frame_ID × 100 ms + a constant (frames are "
                         "expected 0.1 s apart)", str(path))  # fmt: skip
    ids, vehicle = np.unique(table["Vehicle_ID"].to_numpy(np.int64), return_inverse=True)
    first = int(frame.min())
    col = frame - first
    v, t = len(ids), int(col.max()) + 1
    if np.unique(vehicle * t + col).size != len(col):
        raise InputError(f"{str(path)!r}: columns 'Vehicle_ID', 'Frame_ID': a vehicle has two rows for one frame",
                         str(path))  # fmt: skip

    def grid(values, fill=np.nan, dtype=float):
        out = np.full((v, t), fill, dtype)
        out[vehicle, col] = values
        return out

    valid = grid(True, False, bool)
    length = np.zeros(v)
    width = np.zeros(v)
    length[vehicle] = table["v_Length"].to_numpy(float) * FEET_M
    width[vehicle] = table["v_Width"].to_numpy(float) * FEET_M
    front = grid(table["Local_Y"].to_numpy(float) * FEET_M)
    lateral = grid(-table["Local_X"].to_numpy(float) * FEET_M)
    lane = grid(table["Lane_ID"].to_numpy(np.int64), NO_LANE, np.int64)
    x = sema(front, valid, T_POS_S, DT_S) - 0.5 * length[:, None]
    y = sema(lateral, valid, T_POS_S, DT_S)
    speed = sema(_derivative(x, valid, DT_S), valid, T_SPEED_S, DT_S)
    accel = _derivative(speed, valid, DT_S)
    rec = Recording(
        source=str(path), dt=DT_S, t0=first * DT_S, vehicle_ids=ids, x=x, y=y, speed=np.maximum(speed, 0.0),
        accel=accel, lane=lane, length=length, width=width, valid=valid, lanes=_lanes(lane, y, valid),
        frame="NGSIM: x = Local_Y − length/2 (centre), y = −Local_X (left positive), feet → m; sEMA-smoothed",
    )  # fmt: skip
    return check_recording(rec)
