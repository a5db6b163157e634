"""YAML and JSON read with limits: the one way hframe-id parses text it did not write.

Parameter, plant and manifest files (YAML) and the messages of a recording (JSON) may come
from anywhere; whatever they hold, reading them ends in a value or in one typed error that
names the file (``where``) and, for YAML, the line. The limits:

- ``MAX_BYTES`` of text (a parameter file is a few kB, a fit's tens of kB);
- ``MAX_DEPTH`` levels of nesting (the files are three or four deep; deeper input used to
  exhaust Python's stack in the parser with a ``RecursionError``);
- ``MAX_ALIAS_NODES`` values added by YAML aliases when expanded (a 3 kB "billion laughs"
  file expands to hundreds of millions of values, and every consumer that walks or prints
  it expands them again);
- a key given twice in one mapping (or JSON object) is an error, not the last one silently
  winning;
- a YAML integer beyond the largest float (``1`` and 400 zeros) is an error where it is
  read, not an ``OverflowError`` in whatever converts it to a float later (a recording's
  JSON samples check each field's number themselves, naming the field).
"""

from __future__ import annotations

import errno
import json
import os
import re
import stat
import sys
from pathlib import Path
from typing import Any, BinaryIO

import yaml

from hframe_id.errors import MAX_SHOWN, HframeIdError, shown

#: Largest text read [bytes]; reading more would only waste memory.
MAX_BYTES = 10 * 2**20
#: Deepest nesting of mappings and lists.
MAX_DEPTH = 32
#: Most values that YAML aliases may add to a document when expanded.
MAX_ALIAS_NODES = 10_000
#: Largest integer read: beyond it no float holds the value (``float(10**400)`` raises).
MAX_INTEGER = sys.float_info.max


class _Refused(yaml.YAMLError):
    """A YAML document beyond a limit, with the mark where it was found."""

    def __init__(self, problem: str, mark: yaml.Mark | None) -> None:
        super().__init__(problem)
        self.problem = problem
        self.problem_mark = mark


class _LimitedLoader(yaml.SafeLoader):
    """PyYAML's safe loader with a depth limit, an alias-expansion limit and duplicate keys
    refused."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self._depth = 0
        self._alias_nodes = 0
        self._sizes: dict[int, int] = {}

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            node = super().compose_node(parent, index)
            self._alias_nodes += self._size(node)
            if self._alias_nodes > MAX_ALIAS_NODES:
                raise _Refused(
                    f"aliases expand to more than {MAX_ALIAS_NODES:,} values; write them out",
                    mark,
                )
            return node
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark
                raise _Refused(f"nested deeper than {MAX_DEPTH} levels", mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def _size(self, node: yaml.Node) -> int:
        """Values in ``node`` with every alias in it expanded (memoized: shared nodes are
        counted without walking them again)."""
        if id(node) not in self._sizes:
            if isinstance(node, yaml.MappingNode):
                children = [n for pair in node.value for n in pair]
            elif isinstance(node, yaml.SequenceNode):
                children = node.value
            else:
                children = []
            self._sizes[id(node)] = 1 + sum(self._size(child) for child in children)
        return self._sizes[id(node)]

    def construct_yaml_int(self, node):
        value = super().construct_yaml_int(node)
        if abs(value) > MAX_INTEGER:
            digits = len(str(abs(value)))
            raise _Refused(f"an integer of {digits} digits, beyond any float", node.start_mark)
        return value

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    if key in seen:
                        raise _Refused(
                            f"key {shown(key)} given twice (lines {seen[key]} and {line})",
                            None,
                        )
                    seen[key] = line
                except TypeError:  # an unhashable key: PyYAML's own error follows
                    continue
        return super().construct_mapping(node, deep)


_LimitedLoader.add_constructor("tag:yaml.org,2002:int", _LimitedLoader.construct_yaml_int)


def _where_in_yaml(err: yaml.YAMLError) -> str:
    """PyYAML's problem and its line/column, on one line (a problem that quotes the file at
    length, e.g. a huge undefined alias name, is cut)."""
    mark = getattr(err, "problem_mark", None)
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    if len(problem) > MAX_SHOWN:
        problem = problem[: MAX_SHOWN - 3] + "..."
    return f"{problem} at line {mark.line + 1}, column {mark.column + 1}" if mark else problem


def load_yaml(text: str, where: str, error: type[HframeIdError]) -> Any:
    """The YAML document in ``text`` (from ``where``); ``error`` naming ``where`` if it is
    not valid YAML or goes beyond a limit."""
    if len(text) > MAX_BYTES:
        raise error(f"{where}: larger than {MAX_BYTES // 2**20} MB")
    loader = _LimitedLoader(text)
    try:
        return loader.get_single_data()
    except _Refused as err:
        raise error(f"{where}: {_where_in_yaml(err)}") from None
    except yaml.YAMLError as err:
        raise error(f"{where}: not valid YAML ({_where_in_yaml(err)})") from None
    except ValueError as err:  # a scalar PyYAML cannot convert, e.g. a date 2026-13-45
        raise error(f"{where}: not valid YAML ({err})") from None
    finally:
        loader.dispose()


class _DuplicateKey(ValueError):
    pass


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    obj = dict(pairs)
    if len(obj) < len(pairs):
        keys = [key for key, _ in pairs]
        twice = next(key for key in keys if keys.count(key) > 1)
        raise _DuplicateKey(f"key {shown(twice)} given twice")
    return obj


_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')
_JSON_BRACKET = re.compile(rb"[\[\]{}]")


def _json_depth(data: bytes) -> int:
    """The deepest nesting of arrays and objects in JSON text (strings skipped)."""
    depth = deepest = 0
    for bracket in _JSON_BRACKET.findall(_JSON_STRING.sub(b'""', data)):
        depth += 1 if bracket in b"[{" else -1
        deepest = max(deepest, depth)
    return deepest


def load_json(data: bytes | str, where: str, error: type[HframeIdError]) -> Any:
    """The JSON value in ``data`` (from ``where``); ``error`` naming ``where`` if it is not
    valid JSON or goes beyond a limit."""
    raw = data.encode() if isinstance(data, str) else data
    if len(raw) > MAX_BYTES:
        raise error(f"{where}: larger than {MAX_BYTES // 2**20} MB")
    # Counting brackets is cheap; only text with that many looks at their nesting.
    if raw.count(b"[") + raw.count(b"{") > MAX_DEPTH and _json_depth(raw) > MAX_DEPTH:
        raise error(f"{where}: nested deeper than {MAX_DEPTH} levels")
    try:
        return json.loads(raw, object_pairs_hook=_unique_keys)
    except _DuplicateKey as err:
        raise error(f"{where}: {err}") from None
    except (ValueError, UnicodeDecodeError) as err:
        raise error(f"{where}: not JSON ({err})") from None


def not_a_file(path: Path) -> str:
    """What ``path``, which is not a regular file, is instead (for the error line)."""
    if path.is_dir():
        return "is a directory, not a file"
    if path.exists():
        return "is a device, pipe or socket, not a file"
    return "no such file"


def open_input(path: Path) -> BinaryIO:
    """``path`` opened for reading in binary. A named pipe that no program writes to reads
    as empty instead of waiting forever (opened without blocking, then read blocking); a
    device is an ``OSError`` (``/dev/zero`` never ends: read whole, it used all memory)."""
    descriptor = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    mode = os.fstat(descriptor).st_mode
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        os.close(descriptor)
        raise OSError(errno.EINVAL, "a device, not a file", str(path))
    os.set_blocking(descriptor, True)
    return open(descriptor, "rb")


def read_text(path: Path, kind: str, error: type[HframeIdError]) -> str:
    """The UTF-8 text of a file of ``kind`` (for the messages); ``error`` for a binary,
    non-UTF-8 or oversized file, ``OSError`` if it cannot be read at all."""
    with open_input(path) as stream:
        data = stream.read(MAX_BYTES + 1)
    if len(data) > MAX_BYTES:
        raise error(f"{path}: larger than {MAX_BYTES // 2**20} MB; not a {kind}")
    if b"\0" in data:
        raise error(f"{path}: binary data, not a {kind}")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(
            f"{path}: not UTF-8 text (byte 0x{data[err.start]:02x} at offset {err.start}); "
            f"save the {kind} as UTF-8"
        ) from None
