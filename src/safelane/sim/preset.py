"""Presets: a named, complete choice of parameters, simulation settings and nominal-planner gains.

Shipped presets live in the package (``safelane/presets/NAME.yaml``, read-only: ``paper`` is the calibrated
one). User presets live outside the package, in :func:`user_preset_dir` — ``$SAFELANE_PRESET_DIR`` when set,
else ``$XDG_CONFIG_HOME/safelane/presets`` or ``~/.config/safelane/presets`` — where ``safelane calibrate
--install`` writes. :func:`load_preset` takes a name (shipped first, then user presets; a user preset cannot
shadow a shipped one) or the path of a YAML file.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import os
from dataclasses import dataclass, field, fields
from pathlib import Path

import yaml

from ..config import read_mapping, validate_model
from ..errors import InputError
from ..params import Params
from ..planners.base import ExpertPlanner, NominalPlanner
from .config import SimConfig

#: The package's own (shipped) presets.
PRESET_DIR = Path(__file__).resolve().parent.parent / "presets"
PLANNER_KEYS = tuple(f.name for f in fields(ExpertPlanner))
_TOP_KEYS = ("name", "params", "sim", "planner", "network", "meta")


class PresetNotFoundError(InputError, FileNotFoundError):
    """No preset of that name or path (an :class:`InputError` and a :class:`FileNotFoundError`)."""


@dataclass(frozen=True)
class Preset:
    """A named, complete choice of parameters and simulation settings."""

    name: str
    params: Params
    sim: SimConfig
    meta: dict
    planner: dict = field(default_factory=dict)  # ExpertPlanner keyword arguments
    source: str | None = None  # the file it was read from
    #: A registered nominal planner distilled from ``planner`` (``paper``: ``mlp_paper``, the paper's kind of
    #: planner), or a model file's path (``reproduce --nominal``), run by the preset's experiments and ``simulate``;
    #: ``None``: the rule-based planner itself.
    network: str | None = None

    def expert(self) -> ExpertPlanner:
        """The rule-based nominal planner with the preset's knobs: what calibration fits and distillation imitates."""
        return ExpertPlanner(**self.planner)

    def nominal(self) -> NominalPlanner:
        """The nominal planner the preset's experiments run: its ``network`` (a registered name or a model file) if
        it names one, else :meth:`expert`."""
        if self.network is None:
            return self.expert()
        from ..planners.registry import load_nominal

        return load_nominal(self.network)

    def to_yaml(self) -> str:
        data = {
            "name": self.name,
            "params": self.params.model_dump(),
            "sim": self.sim.model_dump(),
            "planner": dict(self.planner),
            **({"network": self.network} if self.network else {}),
            "meta": self.meta,
        }
        return yaml.safe_dump(data, sort_keys=False)


def user_preset_dir() -> Path:
    """Where user presets live: ``$SAFELANE_PRESET_DIR``, else ``$XDG_CONFIG_HOME/safelane/presets``, else
    ``~/.config/safelane/presets`` (never inside the package)."""
    if os.environ.get("SAFELANE_PRESET_DIR"):
        return Path(os.environ["SAFELANE_PRESET_DIR"]).expanduser()
    base = os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config"
    return Path(base).expanduser() / "safelane" / "presets"


def available_presets() -> dict[str, Path]:
    """Every preset name → its file: shipped ones, then user ones that do not reuse a shipped name."""
    found: dict[str, Path] = {}
    for folder in (PRESET_DIR, user_preset_dir()):
        if folder.is_dir():
            for path in sorted(folder.glob("*.yaml")):
                found.setdefault(path.stem, path)
    return found


def _looks_like_path(text: str) -> bool:
    return any(sep in text for sep in ("/", os.sep)) or text.endswith((".yaml", ".yml", ".json"))


def preset_path(name_or_path: str | Path) -> Path:
    """The file of a preset name or path; :class:`PresetNotFoundError` listing the available names otherwise."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or _looks_like_path(text):
        path = Path(name_or_path).expanduser()
        if not path.is_file():
            why = "is a directory" if path.is_dir() else "not found"
            raise PresetNotFoundError(f"preset file {text!r} {why}; expected a preset YAML file", where=text)
        return path
    presets = available_presets()
    if text not in presets:
        names = ", ".join(sorted(presets)) or "none"
        raise PresetNotFoundError(
            f"preset {text!r} not found (available: {names}; or give the path of a preset YAML file; "
            f"user presets live in {user_preset_dir()})",
            where=text,
        )
    return presets[text]


def load_preset(name_or_path: str | Path | Preset = "paper") -> Preset:
    """Load a preset by name (shipped, then user presets) or from a YAML path; a :class:`Preset` passes through.

    Every problem raises :class:`InputError` naming the file, the key and the value."""
    if isinstance(name_or_path, Preset):
        return name_or_path
    if not isinstance(name_or_path, str | Path):
        raise InputError(
            f"preset must be a preset name, a path or a Preset; got {type(name_or_path).__name__}", where="preset"
        )
    path = preset_path(name_or_path)
    stat = path.stat()
    found = _read_preset(str(path), stat.st_mtime_ns, stat.st_size)
    return dataclasses.replace(found, meta=copy.deepcopy(found.meta), planner=copy.deepcopy(found.planner))


@functools.lru_cache(maxsize=32)
def _read_preset(src: str, mtime_ns: int, size: int) -> Preset:
    """The preset in file ``src`` (parsed and checked once per version of the file: an experiment reads its preset
    for every cell, and YAML parsing took a third of a 1,000-scenario cell's time)."""
    path = Path(src)
    data = read_mapping(path, "preset")
    unknown = set(data) - set(_TOP_KEYS)
    if unknown:
        raise InputError(f"{src}: unknown preset keys {sorted(unknown)} (allowed: {', '.join(_TOP_KEYS)})", src)
    sections = {}
    for key in ("params", "sim", "planner", "meta"):
        value = data.get(key) or {}
        if not isinstance(value, dict):
            raise InputError(f"{src}: {key!r} must be a mapping; got {type(value).__name__}", src)
        sections[key] = value
    bad = set(sections["planner"]) - set(PLANNER_KEYS)
    if bad:
        raise InputError(f"{src}: unknown planner keys {sorted(bad)} (allowed: {', '.join(PLANNER_KEYS)})", src)
    try:
        ExpertPlanner(**sections["planner"])
    except (TypeError, ValueError) as exc:
        raise InputError(f"{src}: planner: {exc}", src) from exc
    network = data.get("network")
    if network is not None:
        from ..planners.registry import NOMINAL_NAMES

        if network not in NOMINAL_NAMES:
            raise InputError(f"{src}: network {network!r} is not a nominal planner (choose one of "
                             f"{', '.join(NOMINAL_NAMES)})", src)  # fmt: skip
    return Preset(
        name=str(data.get("name", path.stem)),
        params=validate_model(Params, sections["params"], src, "params."),
        sim=validate_model(SimConfig, sections["sim"], src, "sim."),
        meta=sections["meta"],
        planner=sections["planner"],
        source=src,
        network=network,
    )


def install_preset(preset: Preset, name: str, folder: Path | None = None) -> Path:
    """Write ``preset`` as the user preset ``name`` (into :func:`user_preset_dir` unless ``folder``)."""
    if not name or _looks_like_path(name) or not name.replace("-", "").replace("_", "").isalnum():
        raise InputError(f"preset name {name!r} must be letters, digits, '-' or '_'", where="--name")
    if (PRESET_DIR / f"{name}.yaml").exists():
        raise InputError(
            f"preset name {name!r} is a shipped preset and cannot be replaced; choose another name", where="--name"
        )
    folder = Path(folder) if folder is not None else user_preset_dir()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.yaml"
    renamed = Preset(name, preset.params, preset.sim, preset.meta, dict(preset.planner), network=preset.network)
    path.write_text(renamed.to_yaml(), encoding="utf-8")
    return path
