"""Checked reading of TOML tables, and a small TOML writer.

:class:`Table` wraps one parsed table with its key path (``axes.camera_azimuth``) so every
error names the key, the value and what was wanted, and :meth:`Table.finish` refuses keys that
nobody read (typos are errors, not silently ignored defaults). :func:`dump_toml` writes the
subset of TOML a rig config needs (strings, integers, floats, booleans, arrays of those, tables
and arrays of tables); ``tomllib`` only reads, and this is too small to justify a dependency.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

from core.errors import ConfigError

__all__ = ["Table", "dump_toml", "read_toml"]

T = TypeVar("T")
_MISSING: Any = object()
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _type_name(value: object) -> str:
    """What a TOML value is, with its article: "an integer", "a table"..."""
    names = {bool: "a boolean", int: "an integer", float: "a float", str: "a string"}
    if isinstance(value, list):
        return "an array"
    return names.get(type(value), "a table" if isinstance(value, Mapping) else type(value).__name__)


class Table:
    """One TOML table being read, with its dotted key path for messages.

    Parameters
    ----------
    data : mapping, the parsed table
    path : str, dotted key path of the table ("" for the document root)
    """

    def __init__(self, data: Mapping[str, Any], path: str = "") -> None:
        self._data = data
        self.path = path
        self._read: set[str] = set()

    def key(self, name: str) -> str:
        """Dotted path of ``name`` in this table."""
        return f"{self.path}.{name}" if self.path else name

    def has(self, name: str) -> bool:
        """Whether the table gives ``name`` (without marking it read)."""
        return name in self._data

    def peek(self, name: str) -> Any:
        """The raw value of ``name`` (None when absent), without marking it read."""
        return self._data.get(name)

    def keys(self) -> list[str]:
        """Every key the table gives, in order (without marking them read)."""
        return list(self._data)

    def _get(self, name: str, default: Any) -> Any:
        self._read.add(name)
        if name in self._data:
            return self._data[name]
        if default is _MISSING:
            raise ConfigError(f"{self.key(name)} is missing")
        return default

    def _wrong(self, name: str, value: object, wanted: str) -> ConfigError:
        return ConfigError(
            f"{self.key(name)} = {value!r} is {_type_name(value)}; expected {wanted}"
        )

    def string(self, name: str, default: Any = _MISSING, *, choices: Sequence[str] = ()) -> Any:
        """A string (or ``default`` when absent), optionally one of ``choices``."""
        value = self._get(name, default)
        if name not in self._data:
            return value
        if not isinstance(value, str):
            raise self._wrong(name, value, "a string")
        if choices and value not in choices:
            raise ConfigError(
                f"{self.key(name)} = {value!r} is not one of {', '.join(map(repr, choices))}"
            )
        return value

    def integer(self, name: str, default: Any = _MISSING) -> Any:
        """An integer (booleans refused)."""
        value = self._get(name, default)
        if name not in self._data:
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._wrong(name, value, "an integer")
        return value

    def number(self, name: str, default: Any = _MISSING) -> Any:
        """A finite float; TOML integers are accepted (``30`` for ``30.0``)."""
        value = self._get(name, default)
        if name not in self._data:
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self._wrong(name, value, "a number")
        if not math.isfinite(value):
            raise ConfigError(f"{self.key(name)} = {value!r} must be finite")
        return float(value)

    def boolean(self, name: str, default: Any = _MISSING) -> Any:
        """A boolean, ``true`` or ``false`` (or ``default`` when absent)."""
        value = self._get(name, default)
        if name not in self._data:
            return value
        if not isinstance(value, bool):
            raise self._wrong(name, value, "true or false")
        return value

    def interval(self, name: str) -> tuple[float, float] | None:
        """An optional ``[low, high]`` pair of numbers."""
        value = self._get(name, None)
        if value is None:
            return None
        if (
            not isinstance(value, list)
            or len(value) != 2
            or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)
        ):
            raise self._wrong(name, value, "an array of two numbers [low, high]")
        if not all(math.isfinite(v) for v in value):
            raise ConfigError(f"{self.key(name)} = {value!r} must be finite")
        return float(value[0]), float(value[1])

    def table(self, name: str, *, required: bool = True) -> Table | None:
        """A sub-table; a missing required one is an error naming the section."""
        value = self._get(name, None)
        if value is None:
            if required:
                raise ConfigError(f"section [{self.key(name)}] is missing")
            return None
        if not isinstance(value, Mapping):
            raise self._wrong(name, value, "a table")
        return Table(value, self.key(name))

    def tables(self, name: str) -> list[Table]:
        """An optional array of tables (``[[name]]``)."""
        value = self._get(name, [])
        if not isinstance(value, list) or not all(isinstance(v, Mapping) for v in value):
            raise self._wrong(name, value, "an array of tables [[...]]")
        return [Table(v, f"{self.key(name)}[{i}]") for i, v in enumerate(value)]

    def finish(self, *, allowed_note: str = "") -> None:
        """Refuse keys that were never read: they are typos or keys of another kind of table."""
        unknown = [k for k in self._data if k not in self._read]
        if unknown:
            known = ", ".join(sorted(self._read)) or "none"
            note = f" ({allowed_note})" if allowed_note else ""
            raise ConfigError(f"unknown key {self.key(unknown[0])}{note}; keys here are: {known}")


def _key(name: str) -> str:
    return name if _BARE_KEY.match(name) else _string(name)


def _string(text: str) -> str:
    escapes = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f"}
    escapes["\r"] = "\\r"
    out = []
    for char in text:
        if char in escapes:
            out.append(escapes[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            out.append(f"\\u{ord(char):04X}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


def _value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ConfigError(f"cannot write the non-finite number {value} to a config")
        return repr(value)
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write {value!r} ({type(value).__name__}) as a TOML value")


def _is_table_array(value: object) -> bool:
    return (
        isinstance(value, list | tuple)
        and len(value) > 0
        and all(isinstance(v, Mapping) for v in value)
    )


def _emit(document: Mapping[str, Any], path: list[str], lines: list[str]) -> None:
    # Plain keys first: in TOML they belong to the table header written just before them.
    for name, value in document.items():
        if value is None or isinstance(value, Mapping) or _is_table_array(value):
            continue
        lines.append(f"{_key(name)} = {_value(value)}")
    for name, value in document.items():
        if isinstance(value, Mapping):
            header = ".".join(_key(p) for p in [*path, name])
            nested = [v for v in value.values() if isinstance(v, Mapping) or _is_table_array(v)]
            # A table holding only tables is defined by its children's headers.
            if not value or len(nested) < len(value):
                lines.extend(["", f"[{header}]"])
            _emit(value, [*path, name], lines)
        elif _is_table_array(value):
            header = ".".join(_key(p) for p in [*path, name])
            for item in value:
                lines.extend(["", f"[[{header}]]"])
                _emit(item, [*path, name], lines)


def dump_toml(document: Mapping[str, Any]) -> str:
    """Write nested mappings as TOML text; ``None`` values are left out.

    Parameters
    ----------
    document : mapping of str to str, int, float, bool, lists of those, mappings, or lists of
        mappings (arrays of tables)

    Returns
    -------
    str, TOML that ``tomllib.loads`` reads back to the same values
    """
    lines: list[str] = []
    _emit(document, [], lines)
    return "\n".join(lines).lstrip("\n") + "\n"


def read_toml(path: str | os.PathLike[str], what: str) -> dict[str, Any]:
    """The tables of a TOML file; ConfigError naming the file (``what`` it is) when unreadable."""
    target = Path(path)
    try:
        text = target.read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"{target}: cannot read the {what} ({error.strerror})") from None
    except UnicodeDecodeError as error:
        raise ConfigError(f"{target}: the {what} is not UTF-8 text ({error})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{target}: not valid TOML: {error}") from None
    except RecursionError:  # arrays nested thousands deep
        raise ConfigError(f"{target}: the {what} is nested too deeply to read") from None
