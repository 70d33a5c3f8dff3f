"""Typed configuration files: YAML/JSON map 1:1 onto the parameter objects; unknown keys are errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TypeVar

import yaml
from pydantic import BaseModel

from .params import Params

M = TypeVar("M", bound=BaseModel)


def load_model(cls: type[M], path: Path | str | None, **overrides) -> M:
    """Load ``cls`` from a YAML/JSON file (or defaults when ``path`` is None), then apply ``overrides``."""
    data: dict = {}
    if path is not None:
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"config file not found: {path}")
        text = path.read_text()
        loaded = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
        if loaded is None:
            loaded = {}
        if not isinstance(loaded, dict):
            raise ValueError(f"{path}: expected a mapping of {cls.__name__} fields, got {type(loaded).__name__}")
        data.update(loaded)
    data.update({k: v for k, v in overrides.items() if v is not None})
    return cls.model_validate(data)


def load_params(path: Path | str | None = None, **overrides) -> Params:
    """``Params`` from a file (defaults when ``path`` is None)."""
    return load_model(Params, path, **overrides)
