"""The identity of what a plant simulates: the scenario's name and a hash of the scenario as
resolved (every field after loading, presets and TTOBench files read, defaults filled in).

The plant publishes it latched (``TOPICS['identity']``); the controller and the profile compare
it with the scenario they loaded and refuse to run on another one. ``origin`` (where the file
was read from) is left out: the same scenario read from another path is the same scenario.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import types
from dataclasses import fields, is_dataclass
from enum import Enum

import numpy as np

IDENTITY_FIELDS = ('scenario', 'sha256')


class Undescribable(TypeError):
    """A value whose content ``content_key`` cannot describe (only its object would do)."""


def content_key(value):
    """A canonical, hashable description of a value's content: equal for equal content, unequal
    wherever a computation could tell the values apart (0.0 and -0.0, 1 and 1.0 and True, a
    tuple and a list; two closures of one function are equal only with equal captured values).
    Raises ``Undescribable`` for an object it cannot look into (no ``__dict__``, not a
    dataclass, a container, a number, a string, an array or a function)."""
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return ('b', bool(value))
    if isinstance(value, (int, np.integer)):
        return ('i', int(value))
    if isinstance(value, (float, np.floating)):
        return ('f', float(value).hex())
    if isinstance(value, (tuple, list)):
        return ('t' if isinstance(value, tuple) else 'l', *(content_key(v) for v in value))
    if isinstance(value, dict):
        return ('d', *sorted(((repr(content_key(k)), content_key(v))
                              for k, v in value.items()), key=lambda item: item[0]))
    if isinstance(value, (set, frozenset)):
        return ('set', *sorted(repr(content_key(v)) for v in value))
    if isinstance(value, np.ndarray):
        return ('a', value.dtype.str, value.shape,
                hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest())
    if isinstance(value, Enum):
        return ('e', type(value).__qualname__, value.name)
    if isinstance(value, types.FunctionType):
        code = value.__code__
        return ('fn', value.__module__, value.__qualname__, code.co_code, content_key(
            code.co_consts), content_key(value.__defaults__),
            content_key(tuple(c.cell_contents for c in value.__closure__ or ())))
    kind = f'{type(value).__module__}.{type(value).__qualname__}'
    if is_dataclass(value):
        return (kind, *((f.name, content_key(getattr(value, f.name))) for f in fields(value)))
    if hasattr(value, '__dict__') and not hasattr(type(value), '__slots__'):
        return (kind, content_key(vars(value)))
    raise Undescribable(f'{kind} has no content to key a cache by')


def scenario_hash(scenario) -> str:
    """SHA-256 of the resolved scenario's content (``content_key``), its ``origin`` left out.
    The same for the same scenario in every process of one installation; Undescribable if a
    part of it has no content to describe."""
    description = content_key(dataclasses.replace(scenario, origin=''))
    return hashlib.sha256(repr(description).encode()).hexdigest()


def scenario_identity(scenario) -> str:
    """The identity text: JSON ``{"scenario": name, "sha256": hash}``."""
    return json.dumps({'scenario': scenario.name, 'sha256': scenario_hash(scenario)},
                      sort_keys=True)


def parse_identity(text: str) -> dict[str, str]:
    """The fields of an identity text; ValueError naming what is wrong."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f'plant identity is not JSON: {error}') from None
    if not isinstance(data, dict) or any(not isinstance(data.get(k), str)
                                         for k in IDENTITY_FIELDS):
        raise ValueError(f'plant identity needs the strings {", ".join(IDENTITY_FIELDS)}, '
                         f'got {text!r}')
    return {k: data[k] for k in IDENTITY_FIELDS}


def identity_mismatch(own: str, plant: str, who: str = 'this node') -> str:
    """'' if the plant simulates the scenario of ``own`` (both identity texts), else why not,
    naming both (``who``: what was given ``own``)."""
    mine, theirs = parse_identity(own), parse_identity(plant)
    if mine == theirs:
        return ''
    same_name = mine['scenario'] == theirs['scenario']
    return (f"the plant simulates scenario {theirs['scenario']} (sha256 "
            f"{theirs['sha256'][:12]}), {who} was given {mine['scenario']} (sha256 "
            f"{mine['sha256'][:12]})" + (': same name, different content' if same_name else '')
            + '; start both with the same scenario parameter')
