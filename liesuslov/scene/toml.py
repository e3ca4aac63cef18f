"""TOML in and out: the reader (stdlib ``tomllib``; ``tomli`` on Python 3.10) and a small writer."""

from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Mapping
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["tomllib", "to_toml", "plain"]


def plain(v: Any) -> Any:
    """Plain-data copy of a TOML document (dates become strings)."""
    if isinstance(v, Mapping):
        return {str(k): plain(e) for k, e in v.items()}
    if isinstance(v, list):
        return [plain(e) for e in v]
    if isinstance(v, (bool, int, float, str)):
        return v
    return str(v)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(e) for e in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(e)}" for k, e in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k, ensure_ascii=False)


def to_toml(data: Mapping[str, Any], _prefix: str = "") -> str:
    """Write plain data (tables, arrays, strings, numbers, booleans) as TOML text; inverse of ``tomllib.loads``."""
    lines = []
    tables = []
    for k, v in data.items():
        if isinstance(v, Mapping):
            tables.append((k, v))
        else:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in tables:
        name = f"{_prefix}.{_toml_key(k)}" if _prefix else _toml_key(k)
        body = to_toml(v, name)
        has_scalars = any(not isinstance(e, Mapping) for e in v.values())
        if has_scalars or not v:
            out += ("\n" if out else "") + f"[{name}]\n" + body
        else:
            out += body
    return out
