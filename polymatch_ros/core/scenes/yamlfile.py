"""Scene text -> plain Python data, refusing what YAML permits but a scene never needs.

Checked before anything is built, on the parser's event stream (no recursion): the file
size, the nesting depth, the number of values after alias expansion (a 600-byte
"billion laughs" file expands to 10^9), duplicate keys (YAML keeps the last one silently)
and non-scalar keys.  Numbers follow YAML 1.2: ``1e-3`` is a float, not the string
"1e-3".  Every refusal is one ``SceneError`` line naming the file or the key path.
"""

import os
import re
from typing import Any

import yaml

from ..errors import SceneError
from .limits import MAX_DEPTH, MAX_FILE_BYTES, MAX_NODES, format_bytes

_BASE: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Loader(_BASE):  # type: ignore[valid-type,misc]
    """SafeLoader (libyaml when available) with YAML 1.2 floats (1e3, 2E-5)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


def read_scene_file(path: str | os.PathLike[str]) -> str:
    """The text of a scene file: a regular file, at most MAX_FILE_BYTES, UTF-8."""
    if os.path.isdir(path):
        raise SceneError(f"{path}: is a directory, not a scene file")
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > MAX_FILE_BYTES:
                raise SceneError(f"{path}: {format_bytes(size)} is more than a scene file may be "
                                 f"({format_bytes(MAX_FILE_BYTES)})")
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise SceneError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(data) > MAX_FILE_BYTES:
        raise SceneError(f"{path}: more than a scene file may be ({format_bytes(MAX_FILE_BYTES)})")
    return decode_text(data, path)


def decode_text(data: bytes, label: object) -> str:
    """UTF-8 (an optional BOM dropped); anything else is refused with the offending byte."""
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise SceneError(f"{label}: is UTF-16 text; scene files must be UTF-8")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{label}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                         f"{exc.start}); scene files are UTF-8 YAML") from None


def parse_yaml(text: str, label: str = "scene") -> Any:
    """Scene data (a dict) from YAML text, or a one-line SceneError."""
    if len(text) > MAX_FILE_BYTES:
        raise SceneError(f"{label}: more than a scene may be ({format_bytes(MAX_FILE_BYTES)})")
    try:
        _check_events(text, label)
        data = yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        where = f"line {mark.line + 1}: " if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SceneError(f"{label}: not valid YAML ({where}{problem})") from None
    except (ValueError, OverflowError, RecursionError) as exc:   # e.g. a 5000-digit integer
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SceneError(f"{label}: not a usable YAML value ({detail})") from None
    if data is None:
        raise SceneError(f"{label}: empty; a scene is a mapping of keys "
                         f"(dimension, groups, ...; see docs/guide/scenes.md)")
    return data


class _Frame:
    """One open collection while walking the event stream."""

    __slots__ = ("path", "mapping", "keys", "key", "size", "anchor", "expect_key")

    def __init__(self, path, mapping, anchor):
        self.path, self.mapping, self.anchor = path, mapping, anchor
        self.keys, self.key, self.size, self.expect_key = {}, None, 1, True


def _child_path(frame, index_or_key):
    if frame is None:
        return ""
    if isinstance(index_or_key, int):
        return f"{frame.path}[{index_or_key}]"
    return f"{frame.path}.{index_or_key}" if frame.path else str(index_or_key)


def _check_events(text, label):
    """Depth, alias expansion and duplicate keys, from the event stream in one linear pass."""
    stack: list[_Frame] = []
    sizes: dict[str, int] = {}
    counts: list[int] = []

    def where(event):
        return f"line {event.start_mark.line + 1}" if event.start_mark else "?"

    def place(size, event):
        """A finished value of ``size`` nodes goes into the innermost open collection."""
        if not stack:
            if size > MAX_NODES:
                raise SceneError(f"{label}: expands to more than {MAX_NODES} values")
            return
        top = stack[-1]
        top.size += size
        if top.size > MAX_NODES:
            raise SceneError(f"{top.path or label}: expands to more than {MAX_NODES} values "
                             f"(aliases of aliases, {where(event)})")
        if top.mapping:
            top.expect_key = not top.expect_key
        else:
            counts[-1] += 1

    def path_here():
        top = stack[-1] if stack else None
        if top is None:
            return ""
        return _child_path(top, top.key if top.mapping else counts[-1])

    for event in yaml.parse(text, Loader=_BASE):
        top = stack[-1] if stack else None
        if isinstance(event, yaml.ScalarEvent):
            if top is not None and top.mapping and top.expect_key:
                _check_key(top, event, label)
            size = 1
            if event.anchor:
                sizes[event.anchor] = size
            place(size, event)
        elif isinstance(event, yaml.AliasEvent):
            if top is not None and top.mapping and top.expect_key:
                raise SceneError(f"{top.path or label}: an alias as a key ({where(event)})")
            place(sizes.get(event.anchor or "", 1), event)
        elif isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            if top is not None and top.mapping and top.expect_key:
                raise SceneError(f"{top.path or label}: keys must be names, not lists or "
                                 f"mappings ({where(event)})")
            if len(stack) >= MAX_DEPTH:
                raise SceneError(f"{path_here() or label}: nested more than {MAX_DEPTH} levels "
                                 f"deep ({where(event)})")
            stack.append(_Frame(path_here(), isinstance(event, yaml.MappingStartEvent),
                                event.anchor))
            counts.append(0)
        elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            frame = stack.pop()
            counts.pop()
            if frame.anchor:
                sizes[frame.anchor] = frame.size
            place(frame.size, event)


def _check_key(frame, event, label):
    key = event.value
    line = event.start_mark.line + 1 if event.start_mark else 0
    if key in frame.keys and key != "<<":
        path = _child_path(frame, key)
        first = frame.keys[key]
        lines = f"lines {first} and {line}" if first != line else f"line {line}"
        raise SceneError(f"{path}: duplicate key ({lines}); YAML would keep only the last")
    frame.keys[key] = line
    frame.key = key
