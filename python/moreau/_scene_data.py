"""Scenes from Python dicts: the dict mirrors a scene file (docs/scene-files.md) and is written
as TOML text for the library's scene-file parser, so a dict scene, a file scene and a compiled
scene with the same content are the same scene, and messages name the key path."""

from __future__ import annotations

import json
import math
from typing import Any, Dict, List, Mapping

import numpy as np


def _value(value: Any, path: str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a valid TOML basic string (\\", \\\\, \\n, \\uXXXX)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v, f"{path}[{i}]") for i, v in enumerate(value)) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_key(k, path)} = {_value(v, f'{path}.{k}')}"
                               for k, v in value.items()) + "}"
    raise ValueError(f"{path}: expected a number, string, bool, list or dict, got "
                     f"{type(value).__name__}")


def _key(key: Any, path: str) -> str:
    if not isinstance(key, str):
        raise ValueError(f"{path}: keys must be strings, got {type(key).__name__}")
    return json.dumps(key)


def _normalize(data: Mapping[str, Any]) -> Dict[str, Any]:
    """Conveniences of the dict form: parameters as {name: value} or {name: (value,
    description)}, and inputs as {name: value} for constant controls."""
    data = dict(data)
    params = data.get("parameters")
    if isinstance(params, Mapping):
        listed: List[Dict[str, Any]] = []
        for name, spec in params.items():
            if isinstance(spec, tuple) and len(spec) == 2:
                listed.append({"name": name, "value": spec[0], "description": spec[1]})
            else:
                listed.append({"name": name, "value": spec})
        data["parameters"] = listed
    inputs = data.get("inputs")
    if isinstance(inputs, Mapping):
        data["inputs"] = [{"name": name, **spec} if isinstance(spec, Mapping)
                          else {"name": name, "value": spec} for name, spec in inputs.items()]
    return data


def to_toml(data: Mapping[str, Any]) -> str:
    """The scene dict as scene-file text: scalars and arrays first, then [defs], then the arrays
    of tables ([[parameters]], [[inputs]], [[effects]])."""
    if not isinstance(data, Mapping):
        raise ValueError(f"a scene dict must be a dict, got {type(data).__name__}")
    data = _normalize(data)
    lines: List[str] = []
    tables: List[str] = []
    for key, value in data.items():
        if isinstance(value, Mapping):
            tables.append(f"[{_key(key, '')}]")
            for k, v in value.items():
                tables.append(f"{_key(k, key)} = {_value(v, f'{key}.{k}')}")
        elif isinstance(value, (list, tuple)) and value and all(isinstance(v, Mapping)
                                                               for v in value):
            for i, item in enumerate(value):
                tables.append(f"[[{_key(key, '')}]]")
                for k, v in item.items():
                    tables.append(f"{_key(k, f'{key}[{i}]')} = {_value(v, f'{key}[{i}].{k}')}")
        else:
            lines.append(f"{_key(key, '')} = {_value(value, key)}")
    return "\n".join(lines + tables) + "\n"
