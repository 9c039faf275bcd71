"""Reading untrusted mappings (YAML files, parameters) with errors that name the field at fault."""

from __future__ import annotations

import difflib
import math
import re
from typing import Any, Iterable, Mapping

# A float in YAML 1.2 (core schema) and Python syntax, without the special values: PyYAML reads
# YAML 1.1, where an exponent without a dot ('2e5') is not a float but text.
NUMBER_TEXT = re.compile(r'[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?')


class ConfigError(ValueError):
    """A configuration file or value is wrong; the message names where and what."""


class DataWarning(UserWarning):
    """A file loads, but a figure of it was changed to keep the physics physical (the message
    names the file, the figure and the bound)."""


#: how close (difflib's ratio) a field not read must be to a missing required one to be named as
#: its typo
TYPO_CUTOFF = 0.85


def likely_meant(name: str, valid: Iterable[str]) -> str | None:
    """The valid name that ``name`` is most likely a typo of (difflib's closest match with its
    default cutoff of 0.6), or None."""
    close = difflib.get_close_matches(name, sorted(valid), n=1)
    return close[0] if close else None


def unknown_field_message(unknown: Iterable[str], valid: Iterable[str], quote=str) -> str:
    """'unknown field(s) per_mile; did you mean per_mille? (valid fields: ...)' for one or more
    unknown names, each with its likely intended name where there is one."""
    valid = sorted(set(valid))
    parts = []
    for name in unknown:
        meant = likely_meant(name, valid)
        parts.append(f'{quote(name)}; did you mean {quote(meant)}?' if meant else quote(name))
    listed = ', '.join(quote(v) for v in valid) if valid else 'none'
    return f'unknown field(s) {", ".join(parts)} (valid fields: {listed})'


def as_number(value: Any) -> float | None:
    """``value`` as a float if it is a number (an int or a float, not a bool) or text that
    NUMBER_TEXT matches ('2e5', '-1.5E-3'); None if it is neither ('nan', 'inf', 'true', 'far').
    A NaN or an infinity (a float, or text that overflows such as '1e999') is returned as it
    is, for the caller to reject."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str) and NUMBER_TEXT.fullmatch(value):
        return float(value)
    return None


class Fields:
    """Typed access to one mapping of a file, with the path of each field for error messages."""

    def __init__(self, data: Any, where: str):
        if not isinstance(data, Mapping):
            raise ConfigError(f'{where or "the file"}: expected a mapping, got '
                              f'{type(data).__name__}')
        self._data = data
        self.where = where
        self._used: set[str] = set()

    def _path(self, key: str) -> str:
        return f'{self.where}.{key}' if self.where else key

    def has(self, key: str) -> bool:
        return key in self._data

    def _missing(self, key: str, what: str) -> ConfigError:
        """A required field is missing: if a field not read so far looks like a typo of it,
        name that field ('unknown field per_mile; did you mean per_mille?')."""
        # A close match (difflib ratio >= 0.85: per_mile/per_mille 0.94) or the key without its
        # unit suffix (max_jerk for max_jerk_mps3), and not a longer name containing the key,
        # which is more likely a valid field not read yet (end_radius_m beside a missing
        # radius_m).
        unread = [k for k in map(str, self._data)
                  if k not in self._used and k != key and key not in k]
        for typo in unread:
            if (key.startswith(typo + '_')
                    or difflib.get_close_matches(typo, [key], n=1, cutoff=TYPO_CUTOFF)):
                return ConfigError(f'{self.where or "the file"}: unknown field {typo}; did you '
                                   f'mean {key}? (the required {what} {key} is missing)')
        return ConfigError(f'{self._path(key)}: required {what} is missing')

    def number(self, key: str, default: float | None = None, *, minimum: float | None = None,
               maximum: float | None = None, exclusive_minimum: bool = False) -> float:
        self._used.add(key)
        if key not in self._data:
            if default is None:
                raise self._missing(key, 'number')
            return float(default)
        given = self._data[key]
        value = as_number(given)
        if value is None:
            raise ConfigError(f'{self._path(key)}: must be a number, got {given!r}')
        if not math.isfinite(value):
            raise ConfigError(f'{self._path(key)}: must be finite, got {value!r}')
        if minimum is not None and (value < minimum or (exclusive_minimum and value == minimum)):
            relation = '>' if exclusive_minimum else '>='
            raise ConfigError(f'{self._path(key)}: must be {relation} {minimum:g}, got {value:g}')
        if maximum is not None and value > maximum:
            raise ConfigError(f'{self._path(key)}: must be <= {maximum:g}, got {value:g}')
        return value

    def text(self, key: str, default: str | None = None) -> str:
        self._used.add(key)
        if key not in self._data:
            if default is None:
                raise self._missing(key, 'text')
            return default
        value = self._data[key]
        if not isinstance(value, str) or not value:
            raise ConfigError(f'{self._path(key)}: must be non-empty text, got {value!r}')
        return value

    def items(self, key: str, required: bool = False) -> list['Fields']:
        self._used.add(key)
        if key not in self._data or self._data[key] is None:
            if required:
                raise self._missing(key, 'list')
            return []
        value = self._data[key]
        if not isinstance(value, list):
            raise ConfigError(f'{self._path(key)}: must be a list, got {type(value).__name__}')
        return [Fields(item, f'{self._path(key)}[{i}]') for i, item in enumerate(value)]

    def section(self, key: str, required: bool = False) -> 'Fields':
        self._used.add(key)
        if key not in self._data or self._data[key] is None:
            if required:
                raise self._missing(key, 'section')
            return Fields({}, self._path(key))
        return Fields(self._data[key], self._path(key))

    def raw(self, key: str, required: bool = False) -> Any:
        """The value as it is, for a sub-parser that takes its own path."""
        self._used.add(key)
        if required and self._data.get(key) is None:
            raise self._missing(key, 'section')
        return self._data.get(key)

    def reject_unknown(self) -> None:
        """Typos in a line file must not pass silently as defaults."""
        unknown = sorted(set(map(str, self._data)) - self._used)
        if unknown:
            raise ConfigError(f'{self.where or "the file"}: '
                              f'{unknown_field_message(unknown, self._used)}')
