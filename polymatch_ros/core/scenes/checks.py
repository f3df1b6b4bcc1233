"""Validation of scene values: every error is a SceneError that starts with its key path.

Types are strict: a number is a YAML number (``"2"`` in quotes is text), a name is text,
``null`` is refused (leave the key out for the default), and every magnitude is checked
before anything is allocated from it.
"""

import difflib
import math
from collections.abc import Collection
from typing import Any

import numpy as np

from ..errors import SceneError

_NUMBERS = (int, float, np.integer, np.floating)
_YAML_TYPES = {bool: "true/false", int: "a number", float: "a number", str: "text",
               list: "a list", dict: "a mapping", type(None): "null"}


def describe(value: object) -> str:
    """How a YAML value reads to the person who wrote it: 'the text "2"', 'a list', ..."""
    if isinstance(value, str):
        shown = value if len(value) <= 40 else value[:37] + "..."
        return f"the text {shown!r}"
    if isinstance(value, (bool, type(None))):
        return "null" if value is None else str(value).lower()
    if isinstance(value, (int, float)):
        return _short_number(value)
    return _YAML_TYPES.get(type(value), type(value).__name__)


def _short_number(value: float) -> str:
    if isinstance(value, int) and abs(value) > 10**15:
        if abs(value) < 10**308:
            return f"{float(value):.3g}"
        return "an integer of more than 308 digits"
    return repr(value)


class Map:
    """A mapping with a key path, that refuses unknown keys and null values."""

    def __init__(self, data: object, path: str, allowed: Collection[str]) -> None:
        if not isinstance(data, dict):
            raise SceneError(f"{path or 'scene'}: expected a mapping of keys, "
                             f"got {describe(data)}")
        for key, value in data.items():
            if key not in allowed:
                raise SceneError(f"{join(path, str(key))}: unknown key"
                                 f"{did_you_mean(str(key), allowed)} "
                                 f"(allowed: {', '.join(allowed)})")
            if value is None:
                raise SceneError(f"{join(path, key)}: no value (null); leave the key out for "
                                 f"the default")
        self.data, self.path = data, path

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = None) -> Any:
        return self.data.get(key, default)

    def at(self, key: str | int) -> str:
        return join(self.path, key)

    def number(self, key: str, default: float | None = None, **checks: Any) -> Any:
        if not self.has(key):
            if default is None:
                raise SceneError(f"{self.at(key)}: required")
            return default
        return number(self.data[key], self.at(key), **checks)

    def text(self, key: str, default: str) -> str:
        if not self.has(key):
            return default
        value = self.data[key]
        if not isinstance(value, str):
            raise SceneError(f"{self.at(key)}: expected text, got {describe(value)}")
        return value

    def flag(self, key: str, default: bool) -> bool:
        value = self.data.get(key, default)
        if not isinstance(value, bool):
            raise SceneError(f"{self.at(key)}: expected true or false, got {describe(value)}")
        return value


def did_you_mean(word: str, allowed: Collection[str]) -> str:
    """``; did you mean 'rotations'?`` when one allowed name is close to ``word``, else ''."""
    close = difflib.get_close_matches(word, list(allowed), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def join(path: str, key: object) -> str:
    if isinstance(key, int) and not isinstance(key, bool):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


def number(value: object, path: str, *, minimum: float | None = None,
           maximum: float | None = None, positive: bool = False, integer: bool = False) -> Any:
    """A YAML number within bounds; integral floats (``1e3``) pass as integers (an ``int``
    whenever ``integer`` is set, else an ``int`` or a ``float``)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, _NUMBERS):
        raise SceneError(f"{path}: expected a number, got {describe(value)}")
    value = value.item() if isinstance(value, np.generic) else value
    if isinstance(value, int) and abs(value) > 2**53:
        value = float(value) if abs(value) < 2**1023 else math.inf
    if not math.isfinite(value):
        raise SceneError(f"{path}: must be a finite number, got {describe(value)}")
    if integer:
        if float(value) != int(value):
            raise SceneError(f"{path}: expected an integer, got {value}")
        value = int(value)
    if positive and not value > 0:
        raise SceneError(f"{path}: must be > 0, got {value}")
    if minimum is not None and value < minimum:
        raise SceneError(f"{path}: must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise SceneError(f"{path}: must be <= {maximum:g}, got {value:g}")
    return value


def _numeric_array(value: object, path: str, want: str) -> np.ndarray:
    """A float array from nested lists of YAML numbers only (no text, no booleans, no ragged)."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, (list, tuple)):
            stack.extend(item)
        elif isinstance(item, (bool, np.bool_)) or not isinstance(item, _NUMBERS):
            raise SceneError(f"{path}: expected {want}, found {describe(item)}")
    try:
        with np.errstate(over="ignore"):
            return np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(f"{path}: expected {want}") from None


def vector(value: object, path: str, dim: int | None = None, *,
           bound: float | None = None) -> np.ndarray:
    want = f"{dim} numbers" if dim else "a list of numbers"
    if not isinstance(value, (list, tuple, np.ndarray)):
        raise SceneError(f"{path}: expected {want}, got {describe(value)}")
    v = _numeric_array(value, path, want)
    if v.ndim != 1 or (dim is not None and v.shape[0] != dim):
        raise SceneError(f"{path}: expected {want}, got {_shape_text(v)}")
    return finite(v, path, bound)


def matrix_rows(value: object, path: str, rows: int, cols: int, *,
                bound: float | None = None) -> np.ndarray:
    want = f"{rows} rows of {cols} numbers"
    if not isinstance(value, (list, tuple, np.ndarray)):
        raise SceneError(f"{path}: expected {want}, got {describe(value)}")
    m = _numeric_array(value, path, want)
    if m.shape != (rows, cols):
        raise SceneError(f"{path}: expected {want}, got {_shape_text(m)}")
    return finite(m, path, bound)


def finite(a: np.ndarray, path: str, bound: float | None = None) -> np.ndarray:
    """Refuse NaN/inf and, with ``bound``, magnitudes beyond it (naming the first entry)."""
    bad = ~np.isfinite(a) if bound is None else ~(np.abs(a) <= bound)
    if np.any(bad):
        idx = np.argwhere(bad)[0]
        where = "".join(f"[{i}]" for i in idx)
        value = a[tuple(idx)]
        limit = "finite" if bound is None or not np.isfinite(value) else f"within +-{bound:g}"
        raise SceneError(f"{path}{where}: must be {limit}, got {value:g}")
    return a


def _shape_text(a: np.ndarray) -> str:
    if a.ndim == 0:
        return "a single number"
    if a.ndim == 1:
        return f"{a.shape[0]} numbers"
    return f"an array of shape {a.shape}"
