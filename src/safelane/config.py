"""Typed configuration files: YAML/JSON map 1:1 onto the parameter objects; unknown keys are errors.

Every problem with a file — missing, a directory, unreadable, a YAML/JSON syntax error, not a mapping, an
unknown key, a value out of range — raises :class:`~safelane.errors.InputError` with one line naming the file
(and line, for syntax errors), the field, the value and what is allowed.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from .errors import InputError, describe_validation_error
from .params import Params

M = TypeVar("M", bound=BaseModel)


def read_mapping(path: Path | str, what: str = "config") -> dict:
    """The mapping in a YAML/JSON file; :class:`InputError` naming the file (and line) for every problem."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{what} file not found: {path}", where=str(path))
    if path.is_dir():
        raise InputError(f"{what} file {path} is a directory; expected a YAML or JSON file", where=str(path))
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{what} file {path} cannot be read: {exc}", where=str(path)) from exc
    try:
        loaded = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}, line {exc.lineno}, column {exc.colno}: invalid JSON: {exc.msg}", str(path)) from exc
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f", line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise InputError(f"{path}{at}: invalid YAML: {problem}", where=str(path)) from exc
    if loaded is None:
        return {}
    if not isinstance(loaded, dict):
        raise InputError(f"{path}: expected a mapping of {what} fields, got {type(loaded).__name__}", str(path))
    return loaded


def validate_model(cls: type[M], data: dict, source: str | None = None, prefix: str = "") -> M:
    """``cls.model_validate(data)`` with a one-line :class:`InputError` naming ``source`` and the field."""
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        allowed = list(cls.model_fields)
        raise InputError(describe_validation_error(exc, source, prefix, allowed), where=source) from exc


def load_model(cls: type[M], path: Path | str | None, **overrides) -> M:
    """Load ``cls`` from a YAML/JSON file (or defaults when ``path`` is None), then apply ``overrides``."""
    data: dict = {}
    if path is not None:
        data.update(read_mapping(path, cls.__name__))
    data.update({k: v for k, v in overrides.items() if v is not None})
    return validate_model(cls, data, None if path is None else str(path))


def load_params(path: Path | str | None = None, **overrides) -> Params:
    """``Params`` from a file (defaults when ``path`` is None)."""
    return load_model(Params, path, **overrides)
