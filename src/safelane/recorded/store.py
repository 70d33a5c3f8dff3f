"""Recordings as compressed ``.npz`` files (lossless: every array of a :class:`~.recording.Recording`, bit for bit)
and :func:`load_recording`, which reads any supported file by its content.

The package ships its sample (three CommonRoad US-101 snippets, ``data/``) in this form, so that replaying it
needs only NumPy: ``tools/convert_realdata.py`` wrote them with :func:`save_npz` from :func:`load_commonroad`, and
``tests/test_recorded_sample.py`` checks that loading the XML through commonroad-io gives the same arrays.
"""

from __future__ import annotations

import dataclasses
import zipfile
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import InputError
from .recording import Lanes, Recording, check_recording

#: Format tag stored in every file (a future layout changes it).
FORMAT = "safelane.recording/1"
_LANE_FIELDS = tuple(f.name for f in dataclasses.fields(Lanes))
_ARRAY_FIELDS = ("vehicle_ids", "x", "y", "speed", "accel", "lane", "length", "width", "valid")


def save_npz(recording: Recording, path) -> Path:
    """Write ``recording`` to ``path`` (``.npz``, compressed)."""
    path = Path(path)
    arrays = {name: getattr(recording, name) for name in _ARRAY_FIELDS}
    arrays.update({f"lanes_{name}": getattr(recording.lanes, name) for name in _LANE_FIELDS})
    meta = {"format": FORMAT, "source": Path(recording.source).name, "frame": recording.frame}
    np.savez_compressed(path, dt=np.float64(recording.dt), t0=np.float64(recording.t0),
                        meta=np.array([f"{k}={v}" for k, v in meta.items()]), **arrays)  # fmt: skip
    return path


def load_npz(path) -> Recording:
    """A recording written by :func:`save_npz`; :class:`~safelane.errors.InputError` naming the file otherwise."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = dict(item.split("=", 1) for item in data["meta"].tolist())
            if meta.get("format") != FORMAT:
                raise InputError(f"{str(path)!r}: not a safelane recording (format {meta.get('format')!r})", str(path))
            lanes = Lanes(**{name: data[f"lanes_{name}"] for name in _LANE_FIELDS})
            arrays = {name: data[name] for name in _ARRAY_FIELDS}
            rec = Recording(source=str(path), dt=float(data["dt"]), t0=float(data["t0"]), lanes=lanes,
                            frame=meta.get("frame", ""), **arrays)  # fmt: skip
    except (KeyError, ValueError, OSError, zipfile.BadZipFile) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{str(path)!r}: not a safelane recording ({type(exc).__name__}: {exc})", str(path)) from exc
    return check_recording(rec)


def sample_paths() -> list[Path]:
    """The shipped sample: three NGSIM US-101 snippets in CommonRoad's conversion (``data/NOTICE``), as ``.npz``."""
    folder = resources.files("safelane.recorded") / "data"
    return sorted(Path(str(p)) for p in folder.iterdir() if p.name.endswith(".npz"))


def kind_of(path) -> str | None:
    """``"commonroad"``, ``"ngsim"``, ``"npz"`` by the file's suffix and first bytes; ``None`` for anything else."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return "npz"
    try:
        with path.open("rb") as fh:
            head = fh.read(4096).decode("utf-8", errors="replace")
    except OSError:
        return None
    if suffix == ".xml":
        return "commonroad" if "<commonRoad" in head else None
    if suffix in (".csv", ".txt", ".tsv"):
        first = head.splitlines()[0] if head else ""
        if "Vehicle_ID" in first or (first[:1].isdigit() and len(first.replace(",", " ").split()) >= 18):
            return "ngsim"
    return None


def load_recording(path) -> Recording:
    """Any supported file: CommonRoad XML (needs commonroad-io), an NGSIM trajectory table, a ``.npz`` recording."""
    from .commonroad_reader import load_commonroad
    from .ngsim import load_ngsim

    kind = kind_of(path)
    if kind is None:
        raise InputError(f"{str(path)!r}: not a CommonRoad scenario (.xml), an NGSIM trajectory file (.csv/.txt) or "
                         "a safelane recording (.npz)", str(path))  # fmt: skip
    return {"commonroad": load_commonroad, "ngsim": load_ngsim, "npz": load_npz}[kind](path)
