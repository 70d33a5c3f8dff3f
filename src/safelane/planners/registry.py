"""Nominal planners registered by name: ``get_nominal("mlp")`` → a :class:`~.base.NominalPlanner`.

One place lists every nominal planner a user (or an experiment, a benchmark, the CLI) can ask for by name, so
there is no if-chain over names anywhere else. Each entry is a factory: ``get_nominal`` builds a fresh planner
on every call (loading the shipped network reads its ``.npz``, so keep the instance when you call it often).

Wherever a nominal planner is chosen by name (``simulate(nominal=...)``, ``--nominal``), the path of a model file
works too: :func:`load_nominal` reads a ``.npz`` as ``safelane train`` writes it (:meth:`~.nn.MLPPlanner.load`)
or an ``.onnx`` as ``safelane export-onnx`` writes it (:class:`~.onnx_io.OnnxPlanner`, needs ``onnxruntime``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError, one_line
from .base import ExpertPlanner, NominalPlanner
from .distilled import load_distilled_planner
from .nn import load_default_planner
from .teacher import OptimalControlTeacher


@dataclass(frozen=True)
class NominalEntry:
    """A registered nominal planner: its name, a factory and a one-line description."""

    name: str
    factory: Callable[[], NominalPlanner]
    description: str


NOMINAL_PLANNERS: dict[str, NominalEntry] = {
    e.name: e
    for e in (
        NominalEntry("expert", ExpertPlanner, "Rule-based PD planner (gap middle at L1's speed, smooth lateral)."),
        NominalEntry("mlp", load_default_planner, "The shipped neural planner (two MLPs; see models/MODEL_CARD.md)."),
        NominalEntry("teacher", OptimalControlTeacher, "Receding-horizon optimal-control teacher of the networks."),
        NominalEntry(
            "mlp_paper",
            load_distilled_planner,
            "The network distilled from the paper preset's calibrated rule-based planner (models/distill_paper.yaml).",
        ),
    )
}

#: Registry order.
NOMINAL_NAMES: tuple[str, ...] = tuple(NOMINAL_PLANNERS)


def get_nominal(name: str) -> NominalPlanner:
    """A new instance of the nominal planner registered as ``name``; ``ValueError`` listing the names otherwise."""
    try:
        entry = NOMINAL_PLANNERS[name]
    except KeyError:
        raise ValueError(f"unknown nominal planner {name!r}; choose one of {', '.join(NOMINAL_NAMES)}") from None
    return entry.factory()


#: The file suffixes :func:`load_nominal` reads as a model (what ``safelane train`` / ``export-onnx`` write).
MODEL_SUFFIXES: tuple[str, ...] = (".npz", ".onnx")


def is_model_path(value) -> bool:
    """Whether ``value`` names a model file rather than a registered planner: a ``Path`` (any ``os.PathLike``), or
    a string that ends in one of :data:`MODEL_SUFFIXES`, holds a folder separator or names an existing file."""
    if isinstance(value, os.PathLike):
        return True
    if not isinstance(value, str) or value in NOMINAL_PLANNERS:
        return False
    return value.lower().endswith(MODEL_SUFFIXES) or "/" in value or os.sep in value or Path(value).exists()


def load_nominal_file(path: str | os.PathLike) -> NominalPlanner:
    """The nominal planner stored in a model file: ``.npz`` (:meth:`~.nn.MLPPlanner.load`) or ``.onnx``
    (:class:`~.onnx_io.OnnxPlanner`). A missing, unreadable or foreign file raises :class:`InputError` naming it."""
    path = Path(path).expanduser()
    suffix = path.suffix.lower()
    if suffix not in MODEL_SUFFIXES:
        raise InputError(f"{path}: a nominal-planner model must be a .npz file (safelane train) or an .onnx file "
                         f"(safelane export-onnx); got {suffix or 'no suffix'!r}", str(path))  # fmt: skip
    if not path.is_file():
        what = "is a folder" if path.is_dir() else "not found"
        raise InputError(f"model file {what}: {path}", str(path))
    if suffix == ".onnx":
        from .onnx_io import OnnxPlanner

        try:
            return OnnxPlanner(path)
        except ImportError:
            raise InputError(f"{path}: running an .onnx model needs onnxruntime: pip install 'safelane[train]' "
                             "(or give the .npz model)", str(path)) from None  # fmt: skip
        except Exception as exc:  # onnxruntime's own errors (protobuf, graph) are not ValueErrors
            raise InputError(f"{path}: not a readable safelane .onnx model ({_one_line(exc)})", str(path)) from exc
    from .nn import MLPPlanner

    try:
        return MLPPlanner.load(path)
    except ValueError as exc:  # already names the file
        raise InputError(_one_line(exc), str(path)) from exc
    except Exception as exc:  # an empty or truncated file: EOFError, BadZipFile, ...
        raise InputError(f"{path}: not a readable .npz model file ({type(exc).__name__}: {_one_line(exc)})",
                         str(path)) from exc  # fmt: skip


def load_nominal(name_or_path: str | os.PathLike) -> NominalPlanner:
    """A registered name (:func:`get_nominal`) or the path of a model file (:func:`load_nominal_file`) → a new
    nominal planner; :class:`InputError` listing what is accepted otherwise."""
    if isinstance(name_or_path, str) and name_or_path in NOMINAL_PLANNERS:
        return get_nominal(name_or_path)
    if is_model_path(name_or_path):
        return load_nominal_file(name_or_path)
    raise InputError(
        f"unknown nominal planner {name_or_path!r}; choose one of {', '.join(NOMINAL_NAMES)} or give the path of a "
        f"model file ({' or '.join(MODEL_SUFFIXES)}, as safelane train / export-onnx write)"
    )


def _one_line(exc: BaseException) -> str:
    return one_line(str(exc)) or type(exc).__name__
