"""Typed reading of parsed TOML / JSON tables, with one-line errors naming file, key path and value.

Mission files (:mod:`companion.mission`) and QGroundControl plans (:mod:`companion.mission.plan_import`)
both arrive as nested dicts and lists. :class:`Table` wraps one table: every accessor checks the
type and range of one key and raises :class:`~companion.errors.UserError` with a message such as

    missions/circle.toml: trajectory.radius: must be > 0, not -3

and :meth:`Table.done` rejects keys nobody asked for (a typo must not be silently ignored).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable
from typing import Any, Literal, overload

from ..errors import UserError


def fail(source: str, path: str, message: str) -> UserError:
    """The error for ``path`` (a dotted key path, or '' for the file itself) in ``source``."""
    where = f"{source}: {path}" if path else source
    return UserError(f"{where}: {message}")


def short(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to one short line (a bad value may be a huge table)."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


def is_number(value: Any) -> bool:
    """A real TOML/JSON number (booleans are not numbers here)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class Table:
    """One table of a parsed file: ``data`` found at key path ``path`` of file ``source``."""

    def __init__(self, data: Any, source: str, path: str = ""):
        if not isinstance(data, dict):
            raise fail(source, path, f"must be a table, not {short(data)}")
        self.data = data
        self.source = source
        self.path = path
        self._used: set[str] = set()

    def key(self, name: str) -> str:
        """The dotted path of ``name`` inside this table."""
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, message: str) -> UserError:
        return fail(self.source, self.key(name), message)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default: Any = None) -> Any:
        self._used.add(name)
        return self.data.get(name, default)

    def require(self, name: str) -> Any:
        self._used.add(name)
        if name not in self.data:
            raise self.error(name, "missing (required)")
        return self.data[name]

    # The overloads say what the checks guarantee: a default or required=True gives a number.
    @overload
    def number(self, name: str, default: float, *, required: bool = False,
               minimum: float | None = None, positive: bool = False,
               maximum: float | None = None) -> float: ...
    @overload
    def number(self, name: str, default: None = None, *, required: Literal[True],
               minimum: float | None = None, positive: bool = False,
               maximum: float | None = None) -> float: ...
    @overload
    def number(self, name: str, default: float | None = None, *, required: bool = False,
               minimum: float | None = None, positive: bool = False,
               maximum: float | None = None) -> float | None: ...
    def number(self, name: str, default: float | None = None, *, required: bool = False,
               minimum: float | None = None, positive: bool = False,
               maximum: float | None = None) -> float | None:
        """A finite number (int or float); ``positive`` means > 0, ``minimum`` means >= minimum."""
        if required:
            value = self.require(name)
        elif name not in self.data:
            self._used.add(name)
            return default
        else:
            value = self.raw(name)
        return check_number(value, self.source, self.key(name), minimum=minimum,
                            positive=positive, maximum=maximum)

    @overload
    def string(self, name: str, default: str, *, required: bool = False,
               choices: Iterable[str] | None = None) -> str: ...
    @overload
    def string(self, name: str, default: None = None, *, required: Literal[True],
               choices: Iterable[str] | None = None) -> str: ...
    @overload
    def string(self, name: str, default: str | None = None, *, required: bool = False,
               choices: Iterable[str] | None = None) -> str | None: ...
    def string(self, name: str, default: str | None = None, *, required: bool = False,
               choices: Iterable[str] | None = None) -> str | None:
        if required:
            value = self.require(name)
        elif name not in self.data:
            self._used.add(name)
            return default
        else:
            value = self.raw(name)
        if not isinstance(value, str):
            raise self.error(name, f"must be a string, not {short(value)}")
        if choices is not None:
            choices = list(choices)
            if value not in choices:
                options = ", ".join(f'"{c}"' for c in choices)
                raise self.error(name, f"must be one of {options}, not {short(value)}")
        return value

    def boolean(self, name: str, default: bool = False) -> bool:
        if name not in self.data:
            self._used.add(name)
            return default
        value = self.raw(name)
        if not isinstance(value, bool):
            raise self.error(name, f"must be true or false, not {short(value)}")
        return value

    @overload
    def point(self, name: str, default: tuple[float, float], *,
              required: bool = False) -> tuple[float, float]: ...
    @overload
    def point(self, name: str, default: None = None, *,
              required: Literal[True]) -> tuple[float, float]: ...
    @overload
    def point(self, name: str, default: tuple[float, float] | None = None, *,
              required: bool = False) -> tuple[float, float] | None: ...
    def point(self, name: str, default: tuple[float, float] | None = None, *,
              required: bool = False) -> tuple[float, float] | None:
        """A pair [x, y] of finite numbers."""
        if required:
            value = self.require(name)
        elif name not in self.data:
            self._used.add(name)
            return default
        else:
            value = self.raw(name)
        north, east = check_row(value, 2, self.source, self.key(name), "[north, east]")
        return north, east

    @overload
    def table(self, name: str, *, required: Literal[True]) -> Table: ...
    @overload
    def table(self, name: str, *, required: bool = False) -> Table | None: ...
    def table(self, name: str, *, required: bool = False) -> Table | None:
        if required:
            value = self.require(name)
        elif name not in self.data:
            self._used.add(name)
            return None
        else:
            value = self.raw(name)
        return Table(value, self.source, self.key(name))

    def done(self) -> None:
        """Reject any key that no accessor asked for, suggesting the nearest known key."""
        for name in self.data:
            if name not in self._used:
                hint = difflib.get_close_matches(str(name), sorted(self._used), n=1)
                extra = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise fail(self.source, self.key(str(name)), f"unknown key{extra}")


def check_number(value: Any, source: str, path: str, *, minimum: float | None = None,
                 positive: bool = False, maximum: float | None = None) -> float:
    if not is_number(value):
        raise fail(source, path, f"must be a number, not {short(value)}")
    try:
        number = float(value)
    except OverflowError:   # a TOML integer too large for a float
        raise fail(source, path, f"must be a finite number, not {short(value)}") from None
    if not math.isfinite(number):
        raise fail(source, path, f"must be a finite number, not {short(value)}")
    if positive and number <= 0:
        raise fail(source, path, f"must be > 0, not {short(value)}")
    if minimum is not None and number < minimum:
        raise fail(source, path, f"must be >= {minimum:g}, not {short(value)}")
    if maximum is not None and number > maximum:
        raise fail(source, path, f"must be <= {maximum:g}, not {short(value)}")
    return number


def check_row(value: Any, size: int, source: str, path: str, form: str) -> tuple[float, ...]:
    """A list of exactly ``size`` finite numbers, e.g. a point [x, y] or a waypoint [t, x, y]."""
    if not isinstance(value, list) or len(value) != size:
        raise fail(source, path, f"must be {form}, not {short(value)}")
    return tuple(check_number(v, source, f"{path}[{i}]") for i, v in enumerate(value))


def check_rows(value: Any, size: int, source: str, path: str, form: str,
               min_rows: int, max_rows: int) -> list[tuple[float, ...]]:
    """A list of rows as :func:`check_row`, between ``min_rows`` and ``max_rows`` of them."""
    if not isinstance(value, list):
        raise fail(source, path, f"must be a list of {form}, not {short(value)}")
    if not min_rows <= len(value) <= max_rows:
        raise fail(source, path, f"needs {min_rows} to {max_rows} entries {form}, "
                                 f"has {len(value)}")
    return [check_row(row, size, source, f"{path}[{i}]", form) for i, row in enumerate(value)]
