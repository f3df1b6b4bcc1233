"""Validation of scene values: every error is a SceneError that starts with its key path."""

import math

import numpy as np

from .errors import SceneError


class Map:
    """A mapping with a key path, that refuses unknown keys."""

    def __init__(self, data, path, allowed):
        if not isinstance(data, dict):
            raise SceneError(f"{path or 'scene'}: expected a mapping, got {type(data).__name__}")
        unknown = [k for k in data if k not in allowed]
        if unknown:
            raise SceneError(f"{join(path, unknown[0])}: unknown key (allowed: {', '.join(allowed)})")
        self.data, self.path = data, path

    def has(self, key):
        return key in self.data and self.data[key] is not None

    def raw(self, key, default=None):
        return self.data.get(key, default)

    def at(self, key):
        return join(self.path, key)

    def number(self, key, default=None, *, minimum=None, positive=False, integer=False):
        if not self.has(key):
            if default is None:
                raise SceneError(f"{self.at(key)}: required")
            return default
        return number(self.data[key], self.at(key), minimum=minimum, positive=positive, integer=integer)


def join(path, key):
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else str(key)


def number(value, path, *, minimum=None, positive=False, integer=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        if isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                raise SceneError(f"{path}: expected a number, got {value!r}") from None
        else:
            raise SceneError(f"{path}: expected a number, got {value!r}")
    if not math.isfinite(value):
        raise SceneError(f"{path}: must be finite, got {value}")
    if integer:
        if float(value) != int(value):
            raise SceneError(f"{path}: expected an integer, got {value}")
        value = int(value)
    if positive and not value > 0:
        raise SceneError(f"{path}: must be > 0, got {value}")
    if minimum is not None and value < minimum:
        raise SceneError(f"{path}: must be >= {minimum}, got {value}")
    return value


def vector(value, path, dim=None):
    try:
        v = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{path}: expected a list of numbers") from None
    if v.ndim != 1 or (dim is not None and v.shape[0] != dim):
        want = f"{dim} numbers" if dim else "a list of numbers"
        raise SceneError(f"{path}: expected {want}, got {value!r}")
    if not np.all(np.isfinite(v)):
        raise SceneError(f"{path}: values must be finite")
    return v


def matrix_rows(value, path, rows, cols):
    try:
        m = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{path}: expected a {rows} x {cols} list of lists") from None
    if m.shape != (rows, cols):
        raise SceneError(f"{path}: expected {rows} rows of {cols} numbers, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise SceneError(f"{path}: values must be finite")
    return m
