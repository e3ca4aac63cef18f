"""Reading a scene document: one TOML table at a time, field by field, with messages naming the field.

:class:`_Table` rejects unknown keys when a table is opened and reads typed values (strings from a
choice, booleans, finite numbers, bounded integers, arrays of given shapes); every error starts with
the file and the field path, e.g. ``scene.toml: [potential].B must be ...``.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

_MISSING = object()
_TOP_KEYS = ("description", "gyroscopic", "case", "body", "constraints", "potential", "initial", "integrate",
             "output", "check")
_BODY_KEYS = ("algebra", "n", "mass_tensor", "principal_moments", "inertia", "structure_constants",
              "representation")
_INTEGRATE_KEYS = ("t_span", "method", "chart", "h", "rtol", "atol", "n_out", "t_eval", "reconstruct",
                   "progress", "form", "backend", "max_steps")
_CALLABLE_PARAMETERS = ("v1", "dv1", "v2", "dv2")
_DEFAULT_N_OUT = 501
# Output times are held in memory (state x times x batch numbers): 10^7 times of a small state is
# already ~1 GB, so a larger n_out is a typo (1e12 would end in a MemoryError deep inside numpy).
_MAX_N_OUT = 10_000_000
# A fixed-step run of more steps than this is a mistake in h, not a computation (integrate gives up
# after max_steps = 10^7 steps anyway, with a less direct message).
_MAX_STEPS = 10_000_000

def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _shape_of(v: Any) -> tuple[int, ...] | None:
    """Shape of a rectangular nested list of numbers, or None."""
    if _is_number(v):
        return ()
    if isinstance(v, list):
        if not v:
            return (0,)
        shapes = {_shape_of(e) for e in v}
        if len(shapes) != 1 or None in shapes:
            return None
        return (len(v),) + shapes.pop()
    return None


def _fits(want: tuple[int | None, ...], shape: tuple[int, ...]) -> bool:
    return len(want) == len(shape) and all(a is None or a == b for a, b in zip(want, shape, strict=True))


def _describe(v: Any) -> str:
    if isinstance(v, bool):
        return f"the boolean {str(v).lower()}"
    if _is_number(v):
        return f"the number {v!r}"
    if isinstance(v, str):
        return f"the string {v!r}"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        s = _shape_of(v)
        if s is None:
            if v and all(isinstance(e, str) for e in v):
                return f"a list of {len(v)} string{'s' if len(v) != 1 else ''}"
            if any(isinstance(e, (str, bool, dict)) for e in v):
                return "a list that contains something other than numbers"
            return "nested lists of unequal lengths"
        if len(s) == 1:
            return f"a list of {s[0]} number{'s' if s[0] != 1 else ''}"
        if len(s) == 2:
            return f"a {s[0]}×{s[1]} matrix"
        return f"an array of shape {s}"
    return f"a {type(v).__name__}"


def _did_you_mean(word: str, options) -> str:
    close = difflib.get_close_matches(str(word), list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class _Table:
    """One TOML table, read field by field; unknown keys are rejected when it is opened."""

    def __init__(self, data: Any, source: str, path: str, allowed: tuple[str, ...] | None = None) -> None:
        self.source, self.path = source, path
        where = f"[{path}]" if path else "the top level"
        if not isinstance(data, Mapping):
            raise TypeError(f"{source}: {where} must be a table, got {_describe(data)}")
        self.data = data
        if allowed is not None:
            unknown = [k for k in data if k not in allowed]
            if unknown:
                k = unknown[0]
                label = f"[{path}].{k}" if path else k
                raise ValueError(f"{source}: unknown key {label}{_did_you_mean(k, allowed)}; the valid keys "
                                 f"of {where} are: {', '.join(allowed)}")

    # ------------------------------------------------------------------ messages
    def field(self, key: str) -> str:
        return f"[{self.path}].{key}" if self.path else key

    def error(self, key: str, msg: str) -> ValueError:
        return ValueError(f"{self.source}: {self.field(key)} {msg}")

    def type_error(self, key: str, expected: str, value: Any) -> TypeError:
        return TypeError(f"{self.source}: {self.field(key)} {expected}, got {_describe(value)}")

    # ------------------------------------------------------------------ access
    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, default: Any = _MISSING) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.error(key, "is required")
        return default

    def table(self, key: str, required: bool = False, allowed: tuple[str, ...] | None = None) -> _Table:
        if key not in self.data:
            if required:
                raise ValueError(f"{self.source}: the table [{key}] is required")
            return _Table({}, self.source, key, allowed)
        if allowed is None:
            allowed = {"integrate": _INTEGRATE_KEYS, "initial": ("omega", "Omega", "xi", "w", "Gamma", "g"),
                       "output": ("name", "dir", "figures")}.get(key)
        path = f"{self.path}.{key}" if self.path else key
        return _Table(self.data[key], self.source, path, allowed)

    def string(self, key: str, default: Any = _MISSING) -> Any:
        v = self.get(key, default)
        if v is default and key not in self.data:
            return v
        if not isinstance(v, str):
            raise self.type_error(key, "must be a string", v)
        return v

    def choice(self, key: str, options: tuple[str, ...], default: Any = _MISSING) -> Any:
        v = self.string(key, default)
        if key in self.data and v not in options:
            raise self.error(key, f"must be one of {', '.join(repr(o) for o in options)}; got {v!r}"
                                  f"{_did_you_mean(v, options)}")
        return v

    def boolean(self, key: str, default: Any = _MISSING) -> Any:
        v = self.get(key, default)
        if key in self.data and not isinstance(v, bool):
            raise self.type_error(key, "must be true or false", v)
        return v

    def number(self, key: str, default: Any = _MISSING) -> Any:
        v = self.get(key, default)
        if key not in self.data:
            return v
        if not _is_number(v):
            raise self.type_error(key, "must be a number", v)
        if not math.isfinite(v):
            raise self.error(key, f"must be finite, got {v!r}")
        return float(v)

    def positive(self, key: str, default: Any = _MISSING) -> Any:
        v = self.number(key, default)
        if key in self.data and v <= 0:
            raise self.error(key, f"must be a positive number, got {self.data[key]!r}")
        return v

    def integer(self, key: str, default: Any = _MISSING, minimum: int | None = None,
                maximum: int | None = None, why: str = "") -> Any:
        """An integer in ``[minimum, maximum]``; ``why`` (a clause) says what the upper bound protects."""
        v = self.get(key, default)
        if key not in self.data:
            return v
        if isinstance(v, float) and v.is_integer():
            v = int(v)  # `n_out = 1e3` is a whole number written as a float: accept it
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.type_error(key, "must be an integer", v)
        if minimum is not None and v < minimum:
            raise self.error(key, f"must be an integer >= {minimum}, got {v}")
        if maximum is not None and v > maximum:
            raise self.error(key, f"must be an integer <= {maximum}{why}, got {v}")
        return v

    def pair(self, key: str) -> tuple[float, float]:
        a = self.array(key, [(2,)], "a list of 2 numbers [t0, t1]")
        if a[0] == a[1]:
            raise self.error(key, f"must have t0 != t1, got {_fmt_list(a)}")
        return float(a[0]), float(a[1])

    def array(self, key: str, shapes: list[tuple[int | None, ...]] | None, expected: str) -> np.ndarray:
        """A numeric array whose shape is one of ``shapes`` (None entries: any length; None: any shape)."""
        v = self.get(key)
        s = _shape_of(v)
        if s is None or s == () or not isinstance(v, list):
            raise self.type_error(key, f"must be {expected}", v)
        if shapes is not None and not any(_fits(w, s) for w in shapes):
            raise ValueError(f"{self.source}: {self.field(key)} must be {expected}, got {_describe(v)}")
        a = np.array(v, dtype=float)
        if not np.all(np.isfinite(a)):
            raise self.error(key, "must contain finite numbers only (no inf or nan)")
        return a


def _fmt_list(a, digits: int = 6) -> str:
    a = np.asarray(a, dtype=float)
    if a.ndim == 0:
        return f"{float(a):.{digits}g}"
    return "[" + ", ".join(_fmt_list(e, digits) for e in a) + "]"
